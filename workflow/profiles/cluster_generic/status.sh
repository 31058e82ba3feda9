#!/usr/bin/env bash
# Status command of the generic cluster executor: "success", "failed" or "running" for job id $1 (a process id
# printed by submit.sh). A job that has ended has its exit status in logs/cluster/<id>.exit; a process that is
# gone without one (killed, the node lost) has failed.
exit_file="logs/cluster/$1.exit"
if [ -f "$exit_file" ]; then
  if [ "$(cat "$exit_file")" = 0 ]; then echo success; else echo failed; fi
elif kill -0 "$1" 2>/dev/null; then
  echo running
else
  sleep 1    # the exit status is written right after the job script ends
  if [ -f "$exit_file" ] && [ "$(cat "$exit_file")" = 0 ]; then echo success; else echo failed; fi
fi

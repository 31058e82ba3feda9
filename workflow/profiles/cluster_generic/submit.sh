#!/usr/bin/env bash
# Submit command of the generic cluster executor (profile config.yaml beside this file): start the job script
# ($1, written by Snakemake) detached, as a process of its own, and print its process id as the job id (sbatch
# prints a job number). The job's output goes to logs/cluster/<job script name>.log and its exit status to
# logs/cluster/<job id>.exit (read by status.sh, as sacct reads the scheduler's record); a line per submission to
# logs/cluster/submitted.tsv (job id, job script), so that a test can count the processes.
set -euo pipefail
jobscript="$1"
mkdir -p logs/cluster
log="logs/cluster/$(basename "$jobscript").log"
nohup bash -c 'bash "$1"; echo $? > "logs/cluster/$$.exit"' job "$jobscript" > "$log" 2>&1 < /dev/null &
printf '%s\t%s\n' "$!" "$(basename "$jobscript")" >> logs/cluster/submitted.tsv
echo "$!"

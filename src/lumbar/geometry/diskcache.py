"""Parsed geometry files kept on disk between processes, addressed by their content.

Every job of the workflow is a new process that loads the Visible Human geometry again; parsing its OBJ meshes and
FE node files is most of that load. :func:`load_or_parse` keeps the arrays a parser returns in one ``.npz`` file per
input file, named by the SHA-256 of the input's bytes together with the kind of parse and a version tag (the mesh
library's version, this module's format): a changed file, another parser version or another format gets another
name, so an entry is never stale and never needs invalidating. The parser's checks ran on the bytes that gave the
entry; the caller's checks on the arrays run on every call.

Location: the environment variable ``LUMBAR_CACHE_DIR`` (an empty value switches the cache off), else
``$XDG_CACHE_HOME/lumbar``, else ``~/.cache/lumbar``. Entries are written atomically (a temporary file renamed), so
concurrent jobs may fill the same cache; a cache that cannot be read or written is skipped with a debug log line:
the result is then the parser's, as without the cache. Removing the folder is always safe.
"""
from __future__ import annotations

import hashlib
import logging
import os
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

ENV = "LUMBAR_CACHE_DIR"
FORMAT = 1


def cache_dir() -> Path | None:
    """The cache folder, or None when ``LUMBAR_CACHE_DIR`` is set to an empty value."""
    v = os.environ.get(ENV)
    if v is not None:
        return Path(v).expanduser() if v.strip() else None
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "lumbar"


def entry_path(path, kind: str, tag: str) -> Path | None:
    """Where the arrays parsed from ``path`` by parser ``kind`` (version ``tag``) are kept (None: cache off)."""
    return entry_for(Path(path).read_bytes(), kind, tag)


def entry_for(content: bytes, kind: str, tag: str) -> Path | None:
    """Where the arrays computed from ``content`` (the bytes the result depends on) by ``kind`` (version ``tag``)
    are kept (None: cache off)."""
    d = cache_dir()
    if d is None:
        return None
    h = hashlib.sha256(content)
    h.update(f"|{kind}|{tag}|format {FORMAT}".encode())
    return d / kind / f"{h.hexdigest()}.npz"


def load_or_parse(path, kind: str, tag: str, parse) -> dict:
    """The arrays ``parse()`` returns for the file ``path`` (a dict of numpy arrays), from the cache when an entry
    for these bytes, this ``kind`` and this ``tag`` exists, else parsed and stored."""
    try:
        entry = entry_path(path, kind, tag)
    except OSError as exc:                    # unreadable input: the parser says what is wrong with it
        log.debug("geometry cache skipped for %s: %s", path, exc)
        entry = None
    return _load_or_store(entry, parse, path)


def load_or_compute(content: bytes, kind: str, tag: str, compute, what: str = "") -> dict:
    """The arrays ``compute()`` returns (a dict of numpy arrays) for an input whose bytes, all of them, are
    ``content`` (e.g. the hashes of several files and the settings), from the cache when an entry for this content,
    ``kind`` and ``tag`` exists, else computed and stored; ``what`` names the input in the debug log."""
    return _load_or_store(entry_for(content, kind, tag), compute, what or kind)


def _load_or_store(entry: Path | None, parse, what) -> dict:
    if entry is not None and entry.is_file():
        try:
            with np.load(entry, allow_pickle=False) as z:
                return {k: z[k] for k in z.files}
        except Exception as exc:  # noqa: BLE001  (a damaged entry of any kind: parse again, below)
            log.debug("geometry cache entry %s not readable (%s): parsing %s", entry, exc, what)
    arrays = parse()
    if entry is not None:
        tmp = entry.with_name(f"{entry.stem}.{os.getpid()}.tmp.npz")
        try:
            entry.parent.mkdir(parents=True, exist_ok=True)
            np.savez(tmp, **arrays)
            os.replace(tmp, entry)
        except OSError as exc:
            log.debug("geometry cache not written for %s: %s", what, exc)
            try:
                tmp.unlink(missing_ok=True)
            except OSError:
                pass
    return arrays

"""Content identity of input files: what a file *holds*, not its name, size or date.

Every input a result depends on (videos, image folders, chain, cameras, histograms,
detections) is identified by the SHA-256 of its content, so a different video of the same
byte size is a different input, and a project copied or moved elsewhere still matches its
results. Hashing a large video takes a while (about 1.5 GB/s), so digests are cached by file
identity: device + inode + size + mtime + ctime. An unchanged file is never read twice; any
write to it (which changes mtime and ctime) or a replacement (a new inode) makes it hashed
again.

The cache is one small file per (device, inode) in :func:`cache_dir` ``/hashes``, written
atomically, so concurrent processes and killed runs cannot corrupt it (a broken entry is a
miss). A file is only cached when its timestamps are older than :data:`RACY_SECONDS` when
hashing starts: a file rewritten within the file system's timestamp granularity could
otherwise keep its old stamps and its old digest ("racy" entries, as git calls them).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import tempfile
import time
from pathlib import Path

#: Files modified less than this many seconds before hashing are not cached.
RACY_SECONDS = 2.0
#: Environment variable naming the cache folder (default: ``$XDG_CACHE_HOME/videotrack``).
CACHE_ENV = "VIDEOTRACK_CACHE_DIR"
_BLOCK = 1 << 20
#: Digests found or computed by this process, by stat key.
_MEMO: dict[tuple, str] = {}


def cache_dir() -> Path:
    """Where the digest cache lives: ``$VIDEOTRACK_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/videotrack``, else ``~/.cache/videotrack``."""
    given = os.environ.get(CACHE_ENV)
    if given:
        return Path(given)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "videotrack"


def _stat_key(st: os.stat_result) -> tuple[int, int, int, int, int]:
    return st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns


def _entry(st: os.stat_result) -> Path:
    return cache_dir() / "hashes" / f"{st.st_dev}-{st.st_ino}"


def _cached(st: os.stat_result) -> str | None:
    key = _stat_key(st)
    if key in _MEMO:
        return _MEMO[key]
    try:
        size, mtime, ctime, digest = _entry(st).read_text(encoding="ascii").split()[:4]
    except (OSError, ValueError, UnicodeDecodeError):
        return None
    if (int(size), int(mtime), int(ctime)) != key[2:] or len(digest) != 64:
        return None
    _MEMO[key] = digest
    return digest


def _store(st: os.stat_result, digest: str, path: Path) -> None:
    entry = _entry(st)
    with contextlib.suppress(OSError):  # no cache (read-only home, ...): hash again next time
        entry.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=entry.parent, prefix=f".{entry.name}.", suffix=".tmp")
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as fh:
                fh.write(f"{st.st_size} {st.st_mtime_ns} {st.st_ctime_ns} {digest} {path}\n")
            os.replace(tmp, entry)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            raise


def sha256_of(path: str | os.PathLike) -> str:
    """SHA-256 (hex) of a file's content, read in full (no cache)."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(_BLOCK), b""):
            digest.update(block)
    return digest.hexdigest()


def content_hash(path: str | os.PathLike) -> str:
    """SHA-256 (hex) of the content of the file ``path``, from the cache when the file is
    unchanged since it was last hashed (same device, inode, size, mtime and ctime).

    Raises OSError (e.g. FileNotFoundError) as ``open`` does.
    """
    path = Path(path)
    started = time.time_ns()
    st = path.stat()
    found = _cached(st)
    if found is not None:
        return found
    digest = sha256_of(path)
    after = path.stat()
    if _stat_key(after) != _stat_key(st):  # changed while read: trust nothing
        return digest
    racy = max(st.st_mtime_ns, st.st_ctime_ns) > started - int(RACY_SECONDS * 1e9)
    if not racy and st.st_ino:  # (no inode numbers on some file systems: no cache)
        _MEMO[_stat_key(st)] = digest
        _store(st, digest, path.absolute())
    return digest


def image_files(folder: str | os.PathLike) -> list[Path]:
    """The images of an image-sequence folder, in the order they are read as frames."""
    from videotrack.detect.video import IMAGE_EXTENSIONS, natural_key

    folder = Path(folder)
    return sorted((p for p in folder.iterdir()
                   if p.suffix.lower() in IMAGE_EXTENSIONS and p.is_file()),
                  key=lambda p: natural_key(p.name))


def video_hash(path: str | os.PathLike) -> str:
    """Content identity of a video: :func:`content_hash` of a file; of an image folder, the
    SHA-256 of its images' names and content hashes, in frame order."""
    path = Path(path)
    if not path.is_dir():
        return content_hash(path)
    digest = hashlib.sha256()
    for image in image_files(path):
        digest.update(f"{image.name}\t{content_hash(image)}\n".encode())
    return digest.hexdigest()


def relative_path(path: str | os.PathLike, base: str | os.PathLike) -> str:
    """``path`` relative to the folder ``base``, with ``/`` separators (as stored in
    sidecars, so a project can be copied or moved); absolute where no relative path exists
    (another drive)."""
    try:
        return Path(os.path.relpath(Path(path).absolute(), Path(base).absolute())).as_posix()
    except ValueError:
        return Path(path).absolute().as_posix()


def relative_message(message: str, base: str | os.PathLike) -> str:
    """A message with the absolute folder ``base`` taken off the paths it names (as stored
    in sidecars, which travel with the project)."""
    prefix = str(Path(base).absolute()) + os.sep
    return message.replace(prefix, "")

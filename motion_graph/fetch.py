"""Download the public CMU subject-13 boxing takes (ASF/AMC) into the user cache, verified by SHA-256.

Standard library only (urllib). Each file is written to ``<name>.part``; an interrupted download is
resumed with an HTTP ``Range`` request (a server that ignores it and answers 200 gets a full
download), the SHA-256 is checked, and the file is renamed into place atomically. Files already
present with the right checksum are skipped without any request.
"""
from __future__ import annotations

import hashlib
import http.client
import os
import re
import urllib.error
import urllib.request
from pathlib import Path

from motion_graph import paths

CMU_BASE_URL = "http://mocap.cs.cmu.edu/subjects"
#: Environment variable that overrides the default base URL (e.g. a mirror).
URL_ENV_VAR = "IGRAPH_FIGHT_CMU_URL"

#: SHA-256 of the files this module knows how to verify (from the mocap README, section 1).
SHA256: dict[str, str] = {
    "13.asf": "eb33390bcbccb739d7622bd583fd9be55020868f68689aa6f2060ad688df10dc",
    "13_17.amc": "f024bfe30728fb01debc868c011df16be5d8cca95e8a734dfe00c59722c4cfd1",
    "13_18.amc": "46f4cddbc8e7a3585d4e887bec6ccc5dc7e71382ad41e28607ff4ebd9b115cb8",
}

_CHUNK = 1 << 16
_USER_AGENT = "igraph-fight-fetch/0.1 (python urllib)"


class FetchError(RuntimeError):
    """A download failed. The message names the URL and the problem."""

    def __init__(self, url: str, problem: str) -> None:
        self.url = url
        self.problem = problem
        super().__init__(f"{url}: {problem}")


def sha256_file(path: str | os.PathLike) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def resolve_base_url(base_url: str = CMU_BASE_URL) -> str:
    """The base URL to use: an explicit non-default argument > $IGRAPH_FIGHT_CMU_URL > CMU_BASE_URL."""
    if base_url == CMU_BASE_URL:
        base_url = os.environ.get(URL_ENV_VAR) or CMU_BASE_URL
    return base_url.rstrip("/")


def cmu_files(takes: tuple[str, ...]) -> list[str]:
    """File names for CMU takes like ``"13_17"``: each subject's ``.asf`` once, then the ``.amc`` files."""
    out: list[str] = []
    for take in takes:
        subject = take.split("_", 1)[0]
        for name in (f"{subject}.asf", f"{take}.amc"):
            if name not in out:
                out.append(name)
    return out


def fetch_cmu(dest: Path | None = None, base_url: str = CMU_BASE_URL, takes: tuple[str, ...] = ("13_17", "13_18"),
              progress: bool = True, timeout: float = 30.0) -> list[Path]:
    """Download CMU ASF/AMC takes (``{base}/{subject}/{file}``) into dest and verify their SHA-256.

    Args:
        dest: target folder; default ``paths.default_fetch_dir() / "cmu" / "asf_amc"`` (found later by
            ``paths.find_mocap_root()`` / ``paths.boxing_takes()``).
        base_url: server root; when left at CMU_BASE_URL, $IGRAPH_FIGHT_CMU_URL overrides it.
        takes: take names ``"<subject>_<trial>"``; only those with a known checksum (see SHA256).
        progress: show a tqdm progress bar per file.
        timeout: socket timeout in seconds for each request.
    Returns:
        the local paths of the ASF and AMC files, in download order.
    Raises:
        ValueError: a take without a known checksum.
        FetchError: network / HTTP failure, interrupted transfer (the ``.part`` is kept for resuming),
            or checksum mismatch (the ``.part`` is deleted).
    """
    names = cmu_files(tuple(takes))
    unknown = [n for n in names if n not in SHA256]
    if unknown:
        raise ValueError(f"no SHA-256 known for {', '.join(unknown)}; can verify only {', '.join(sorted(SHA256))}")
    dest = Path(dest) if dest is not None else paths.default_fetch_dir() / "cmu" / "asf_amc"
    dest.mkdir(parents=True, exist_ok=True)
    base = resolve_base_url(base_url)
    out: list[Path] = []
    for name in names:
        subject = name.split(".")[0].split("_")[0]
        out.append(_fetch_one(f"{base}/{subject}/{name}", dest / name, SHA256[name], progress, timeout))
    return out


def _fetch_one(url: str, final: Path, sha: str, progress: bool, timeout: float) -> Path:
    """Make `final` hold the verified file from `url`, resuming `final.part` when present."""
    if final.is_file() and sha256_file(final) == sha:
        return final
    part = final.with_name(final.name + ".part")
    resume = part.is_file() and part.stat().st_size > 0
    if not _download(url, part, resume, progress, timeout) and resume:
        # The server refused the range (416) or answered a different one: start over.
        part.unlink(missing_ok=True)
        _download(url, part, False, progress, timeout)
    got = sha256_file(part)
    if got != sha:
        size = part.stat().st_size
        part.unlink(missing_ok=True)
        raise FetchError(url, f"SHA-256 mismatch: expected {sha}, got {got} ({size} bytes); "
                              f"the partial file was deleted, run again to retry")
    os.replace(part, final)
    return final


def _download(url: str, part: Path, resume: bool, progress: bool, timeout: float) -> bool:
    """Fetch url into part (appending from its current size when resume). False if the resume was refused."""
    offset = part.stat().st_size if resume else 0
    headers = {"User-Agent": _USER_AGENT, "Accept-Encoding": "identity"}
    if offset:
        headers["Range"] = f"bytes={offset}-"
    try:
        resp = urllib.request.urlopen(urllib.request.Request(url, headers=headers), timeout=timeout)
    except urllib.error.HTTPError as e:
        e.close()
        if e.code == 416 and offset:
            return False
        raise FetchError(url, f"HTTP {e.code} {e.reason}") from None
    except (urllib.error.URLError, OSError) as e:
        reason = getattr(e, "reason", None) or e
        raise FetchError(url, f"cannot connect: {reason}") from None
    with resp:
        status = resp.status
        if status == 206 and offset:
            m = re.match(r"bytes\s+(\d+)-", resp.headers.get("Content-Range", ""))
            if not m or int(m.group(1)) != offset:
                return False
            mode = "ab"
        elif status == 200:
            offset, mode = 0, "wb"  # no Range support (or no resume): full download
        else:
            raise FetchError(url, f"unexpected HTTP status {status}")
        length = resp.headers.get("Content-Length")
        expected = int(length) if length and length.isdigit() else None
        received = 0
        bar = None
        if progress:
            from tqdm import tqdm
            bar = tqdm(total=None if expected is None else offset + expected, initial=offset, unit="B",
                       unit_scale=True, unit_divisor=1024, desc=part.name[:-len(".part")], leave=False)
        try:
            with open(part, mode) as fh:
                while True:
                    try:
                        chunk = resp.read(_CHUNK)
                    except (OSError, http.client.HTTPException) as e:
                        raise FetchError(url, f"download interrupted after {offset + received} bytes ({e}); "
                                              f"partial file kept at {part}, run again to resume") from None
                    if not chunk:
                        break
                    fh.write(chunk)
                    received += len(chunk)
                    if bar is not None:
                        bar.update(len(chunk))
                fh.flush()
                os.fsync(fh.fileno())
        finally:
            if bar is not None:
                bar.close()
        if expected is not None and received < expected:
            raise FetchError(url, f"connection closed after {offset + received} of {offset + expected} bytes; "
                                  f"partial file kept at {part}, run again to resume")
    return True

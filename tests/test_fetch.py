"""motion_graph.fetch against a local HTTP server (127.0.0.1, ephemeral port) serving the real CMU files."""
from __future__ import annotations

import hashlib
import re
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import pytest

from motion_graph import fetch, paths
from motion_graph.fetch import SHA256, FetchError, fetch_cmu

NAMES = ("13.asf", "13_17.amc", "13_18.amc")


class _Handler(BaseHTTPRequestHandler):
    """GET /<subject>/<file> from server.root, with Range support and fault injection (see _Server)."""

    protocol_version = "HTTP/1.1"

    def log_message(self, *args: object) -> None:  # keep test output quiet
        pass

    def do_GET(self) -> None:  # noqa: N802 (http.server API)
        srv: _Server = self.server  # type: ignore[assignment]
        rng = self.headers.get("Range")
        with srv.lock:
            srv.requests.append((self.path, rng))
        name = self.path.rsplit("/", 1)[-1]
        f = srv.root / name
        if not re.fullmatch(r"/13/[\w.]+", self.path) or not f.is_file():
            self._send(404, b"not found")
            return
        data = f.read_bytes()
        if name in srv.corrupt:
            i = len(data) // 2
            data = data[:i] + bytes([data[i] ^ 0xFF]) + data[i + 1:]
        start = 0
        m = re.fullmatch(r"bytes=(\d+)-", rng or "")
        if m and not srv.ignore_range:
            start = int(m.group(1))
            if start >= len(data):
                self._send(416, b"", {"Content-Range": f"bytes */{len(data)}"})
                return
        body = data[start:]
        headers = {"Content-Type": "application/octet-stream", "Content-Length": str(len(body)),
                   "Accept-Ranges": "bytes"}
        if start:
            headers["Content-Range"] = f"bytes {start}-{len(data) - 1}/{len(data)}"
        with srv.lock:
            cut = srv.cut.pop(name, None)  # only the first request for that file is cut
        self.send_response(206 if start else 200)
        for k, v in headers.items():
            self.send_header(k, v)
        self.send_header("Connection", "close")
        self.end_headers()
        self.wfile.write(body if cut is None else body[:cut])
        self.wfile.flush()
        self.close_connection = True

    def _send(self, code: int, body: bytes, extra: dict[str, str] | None = None) -> None:
        self.send_response(code)
        for k, v in (extra or {}).items():
            self.send_header(k, v)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Connection", "close")
        self.end_headers()
        self.wfile.write(body)
        self.close_connection = True


class _Server(ThreadingHTTPServer):
    daemon_threads = True

    def __init__(self, root: Path) -> None:
        super().__init__(("127.0.0.1", 0), _Handler)
        self.root = root
        self.lock = threading.Lock()
        self.requests: list[tuple[str, str | None]] = []
        self.corrupt: set[str] = set()      # serve these with one byte flipped
        self.cut: dict[str, int] = {}       # first request for name: close after N body bytes
        self.ignore_range = False           # answer 200 with the full file even to Range requests

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.server_address[1]}"


@pytest.fixture(scope="module")
def served_dir(mocap_root: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    src = mocap_root / "cmu" / "asf_amc"
    d = tmp_path_factory.mktemp("served")
    for n in NAMES:
        (d / n).write_bytes((src / n).read_bytes())  # plain copy: the source files are read-only
    return d


@pytest.fixture
def server(served_dir: Path):
    srv = _Server(served_dir)
    t = threading.Thread(target=srv.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
    t.start()
    try:
        yield srv
    finally:
        srv.shutdown()
        srv.server_close()
        t.join(timeout=5)
        assert not t.is_alive()


@pytest.fixture(autouse=True)
def _no_env_url(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(fetch.URL_ENV_VAR, raising=False)


def _sha(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def test_sums_match_readme_copies(served_dir: Path) -> None:
    for n in NAMES:
        assert _sha(served_dir / n) == SHA256[n]


def test_fetch_verifies_and_writes(server: _Server, tmp_path: Path) -> None:
    out = fetch_cmu(tmp_path, base_url=server.url, progress=False, timeout=5)
    assert [p.name for p in out] == list(NAMES)
    for p in out:
        assert p.parent == tmp_path and _sha(p) == SHA256[p.name]
    assert not list(tmp_path.glob("*.part"))
    assert sorted(r[0] for r in server.requests) == sorted(f"/13/{n}" for n in NAMES)
    assert all(r[1] is None for r in server.requests)


def test_second_call_skips(server: _Server, tmp_path: Path) -> None:
    fetch_cmu(tmp_path, base_url=server.url, progress=False, timeout=5)
    server.requests.clear()
    out = fetch_cmu(tmp_path, base_url=server.url, progress=False, timeout=5)
    assert server.requests == []
    assert all(_sha(p) == SHA256[p.name] for p in out)


def test_bad_checksum_raises_and_leaves_nothing(server: _Server, tmp_path: Path) -> None:
    server.corrupt.add("13_17.amc")
    with pytest.raises(FetchError, match="SHA-256 mismatch") as ei:
        fetch_cmu(tmp_path, base_url=server.url, progress=False, timeout=5)
    assert ei.value.url == f"{server.url}/13/13_17.amc"
    assert ei.value.url in str(ei.value)
    assert not (tmp_path / "13_17.amc").exists()
    assert not (tmp_path / "13_17.amc.part").exists()
    assert _sha(tmp_path / "13.asf") == SHA256["13.asf"]  # fetched before the bad one


def test_interrupted_download_resumes_with_range(server: _Server, tmp_path: Path) -> None:
    cut = 100_000
    server.cut["13_17.amc"] = cut
    with pytest.raises(FetchError, match="resume"):
        fetch_cmu(tmp_path, base_url=server.url, progress=False, timeout=5)
    part = tmp_path / "13_17.amc.part"
    assert part.stat().st_size == cut
    assert not (tmp_path / "13_17.amc").exists()

    server.requests.clear()
    out = fetch_cmu(tmp_path, base_url=server.url, progress=True, timeout=5)
    assert ("/13/13_17.amc", f"bytes={cut}-") in server.requests
    assert ("/13/13.asf", None) not in server.requests  # already complete: skipped
    assert all(_sha(p) == SHA256[p.name] for p in out)
    assert not part.exists()


def test_server_ignoring_range_gets_full_download(server: _Server, tmp_path: Path) -> None:
    server.ignore_range = True
    (tmp_path / "13_18.amc.part").write_bytes(b"garbage that must be discarded\n" * 10)
    out = fetch_cmu(tmp_path, base_url=server.url, takes=("13_18",), progress=False, timeout=5)
    assert [p.name for p in out] == ["13.asf", "13_18.amc"]
    assert ("/13/13_18.amc", "bytes=310-") in server.requests
    assert _sha(tmp_path / "13_18.amc") == SHA256["13_18.amc"]


def test_complete_part_answered_416_is_redownloaded(server: _Server, served_dir: Path, tmp_path: Path) -> None:
    data = (served_dir / "13.asf").read_bytes()
    (tmp_path / "13.asf.part").write_bytes(data + b"extra")
    fetch_cmu(tmp_path, base_url=server.url, takes=("13_18",), progress=False, timeout=5)
    asf = [r for r in server.requests if r[0] == "/13/13.asf"]
    assert asf == [("/13/13.asf", f"bytes={len(data) + 5}-"), ("/13/13.asf", None)]
    assert _sha(tmp_path / "13.asf") == SHA256["13.asf"]


def test_http_error_names_url(server: _Server, tmp_path: Path) -> None:
    with pytest.raises(FetchError, match="HTTP 404") as ei:
        fetch_cmu(tmp_path, base_url=server.url + "/nowhere", progress=False, timeout=5)
    assert ei.value.url == f"{server.url}/nowhere/13/13.asf"


def test_unknown_take_rejected_before_any_request(server: _Server, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="14_01.amc"):
        fetch_cmu(tmp_path, base_url=server.url, takes=("14_01",), progress=False)
    assert server.requests == []


def test_env_url_and_default_dest_found_by_paths(server: _Server, tmp_path: Path,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(fetch.URL_ENV_VAR, server.url + "/")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.delenv(paths.ENV_VAR, raising=False)
    out = fetch_cmu(progress=False, timeout=5)
    root = paths.default_fetch_dir()
    assert root == tmp_path / "cache" / "igraph-fight" / "mocap"
    assert all(p.parent == root / "cmu" / "asf_amc" for p in out)
    assert len(server.requests) == 3
    # find_mocap_root falls through to the cache when no shared folder exists.
    assert root in paths.candidate_mocap_roots()
    monkeypatch.setattr(paths, "candidate_mocap_roots", lambda: [tmp_path / "no_shared", root])
    assert paths.find_mocap_root() == root
    assert [p.name for p in paths.boxing_takes(root)] == ["13_17.amc", "13_18.amc"]

"""``lfcodec serve DIR``: a small HTTP file server with byte ranges, for local use and tests.

GET and HEAD of files inside DIR (nothing outside it: paths are resolved and confined), one
``Range: bytes=a-b`` per request (``206`` with ``Content-Range``; ``416`` when unsatisfiable or
malformed; a request for several ranges gets the whole file, ``200``),
a strong ``ETag`` from the file's size and modification time, ``If-Match`` (``412`` when the
file changed). ``latency_s`` delays every answer, to stand for a network in benchmarks.

With ``viewer=True`` the browser viewer's files (``formats/web``: HTML, JavaScript, the
OpenJPEG WebAssembly decoder) are served under ``/_viewer/``; :func:`viewer_url` gives the
page's address for a file (``lfcodec view``).
"""
from __future__ import annotations

import re
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import unquote, urlsplit

from .errors import ParameterError

_RANGE = re.compile(r"^bytes=(\d*)-(\d*)$")
#: the browser viewer's files (shipped in the package)
WEB_DIR = Path(__file__).resolve().parent / "web"
VIEWER_PREFIX = "_viewer/"
_TYPES = {".html": "text/html; charset=utf-8", ".js": "text/javascript; charset=utf-8", ".wasm": "application/wasm",
          ".json": "application/json", ".md": "text/plain; charset=utf-8", ".png": "image/png"}
#: viewer files the server hands out (not package.json, node_modules, …)
_WEB_FILES = ("index.html", "lfc.js", "lfn.js", "lfn_kernel.js", "lfn_pool.js", "lfn_worker.js", "tiles.js", "render.js",
              "render_pool.js", "render_worker.js", "render_kernel.js", "predict.js",
              "predict_kernel.js", "wasm_module.js", "viewer.js", "openjpeg.js",
              "vendor/openjpegwasm_decode.js",
              "vendor/openjpegwasm_decode.wasm", "vendor/LICENSES.md")


def viewer_url(base: str, name: str) -> str:
    """The viewer page's URL for file ``name`` (relative to the served folder) on server ``base``.
    The ``file`` parameter is the file's URL path, percent-encoded, then encoded again as a query
    value: the page resolves it as a URL, where a raw ``#`` or ``?`` in a name would start a
    fragment or a query."""
    from urllib.parse import quote

    return f"{base.rstrip('/')}/{VIEWER_PREFIX}index.html?file={quote('/' + quote(name), safe='/')}"


def make_handler(root: Path, latency_s: float = 0.0, ranges: bool = True, viewer: bool = False):
    """A request handler class serving ``root`` (``ranges=False``: a server that ignores
    Range headers, to test clients against one; ``viewer``: also the viewer's files)."""
    root = Path(root).resolve()

    class Handler(BaseHTTPRequestHandler):
        protocol_version = "HTTP/1.1"

        def log_message(self, *args):                  # quiet: this is a tool, not a web server
            pass

        def _file(self) -> Path | None:
            rel = unquote(urlsplit(self.path).path).lstrip("/")
            if viewer and rel.startswith(VIEWER_PREFIX):
                name = rel[len(VIEWER_PREFIX):]
                return WEB_DIR / name if name in _WEB_FILES and (WEB_DIR / name).is_file() else None
            p = (root / rel).resolve()
            if (p != root and root not in p.parents) or not p.is_file():
                return None
            return p

        def _error(self, code: int, extra: dict | None = None):
            self.send_response(code)
            for k, v in (extra or {}).items():
                self.send_header(k, v)
            self.send_header("Content-Length", "0")
            self.end_headers()

        def _serve(self, head: bool):
            if latency_s:
                time.sleep(latency_s)
            p = self._file()
            if p is None:
                return self._error(404)
            st = p.stat()
            size = st.st_size
            etag = f'"{size:x}-{st.st_mtime_ns:x}"'
            im = self.headers.get("If-Match")
            if im is not None and im.strip() not in (etag, "*"):
                return self._error(412)
            rng = self.headers.get("Range") if ranges else None
            if rng is not None and "," in rng:         # several ranges: ignored (RFC 9110 allows it), the whole file
                rng = None
            a, b, code = 0, size - 1, 200
            if rng is not None:
                m = _RANGE.match(rng.strip())
                if not m or (m.group(1) == "" and m.group(2) == ""):
                    return self._error(416, {"Content-Range": f"bytes */{size}"})
                if m.group(1) == "":                   # suffix range: the last n bytes
                    a, b = max(0, size - int(m.group(2))), size - 1
                else:
                    a = int(m.group(1))
                    b = min(int(m.group(2)), size - 1) if m.group(2) else size - 1
                if a >= size or a > b:
                    return self._error(416, {"Content-Range": f"bytes */{size}"})
                code = 206
            self.send_response(code)
            self.send_header("Content-Type", _TYPES.get(p.suffix.lower(), "application/octet-stream"))
            self.send_header("Accept-Ranges", "bytes" if ranges else "none")
            self.send_header("ETag", etag)
            self.send_header("Content-Length", str(b - a + 1))
            if code == 206:
                self.send_header("Content-Range", f"bytes {a}-{b}/{size}")
            self.end_headers()
            if not head:
                with open(p, "rb") as fh:
                    fh.seek(a)
                    self.wfile.write(fh.read(b - a + 1))

        def do_GET(self):
            self._serve(head=False)

        def do_HEAD(self):
            self._serve(head=True)

    return Handler


class FileServer:
    """A threaded server of ``root`` on ``host:port`` (port 0 = any free port).

    Use as a context manager in tests (``url_of(name)``), or :meth:`serve_forever`.
    """

    def __init__(self, root, host: str = "127.0.0.1", port: int = 0, latency_s: float = 0.0, ranges: bool = True,
                 viewer: bool = False):
        self.root = Path(root)
        try:
            self.httpd = ThreadingHTTPServer((host, port), make_handler(self.root, latency_s, ranges, viewer))
        except OSError as e:                      # (a port in use, an address this machine does not have)
            raise ParameterError(f"cannot listen on {host}:{port} ({e.strerror or e}); give another --port (0 "
                                 f"picks a free one) or --host") from None
        self.httpd.daemon_threads = True
        self.host, self.port = self.httpd.server_address[:2]
        self._thread = None

    def url_of(self, name: str) -> str:
        return f"http://{self.host}:{self.port}/{name}"

    def viewer_url(self, name: str) -> str:
        """The viewer page for file ``name`` of the served folder (a server made with ``viewer=True``)."""
        return viewer_url(f"http://{self.host}:{self.port}", name)

    def serve_forever(self) -> None:
        self.httpd.serve_forever()

    def __enter__(self):
        self._thread = threading.Thread(target=self.httpd.serve_forever, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self.httpd.shutdown()
        self.httpd.server_close()

"""``physmotion serve``: a local web app and JSON endpoint that keep one model warm.

:func:`make_app` builds the app (FastAPI; testable in-process), :func:`serve` runs it under uvicorn. The
model is loaded once; every motion is made by :func:`physmotion.generate.generate` in one worker
thread, one request at a time. At most ``ServeConfig.waiting`` requests wait behind the running one;
past that a request is refused at once with 503 and a ``Retry-After``, so a burst never piles up work
and every request gets an answer. A request whose client goes away (checked every 0.25 s while it
waits for its motion) gives its place up at once: one still waiting is dropped unmade, a running one
stops at its next sampling step or P run (its motion is not kept). Bad input gets a 4xx answer with
``{"error": "<one line>"}``.

Before a request reaches a route: a Host header that is not a name of the server (``LOCAL_HOSTS``,
the bound address unless it is 0.0.0.0 or ::, ``ServeConfig.allowed_hosts``; any port) gets 400, so
a foreign page cannot reach the server by DNS rebinding; a body over ``ServeConfig.max_body`` bytes
(16 KiB) gets 413 before it is parsed (by its Content-Length, or counted as it arrives when chunked).

Routes:

- ``GET /``: the page (prompt, physics mode, seconds, seed; the motion plays in the viewer of
  ``physmotion view``, in an iframe; downloads). Only local assets: the vendored three.js is inlined.
- ``POST /api/generate``: ``{"text": str, "physics": str, "seconds": float | null, "seed": int}`` ->
  ``{"id", "text", "physics", "seconds", "seed", "fps", "frames", "joints": (T, 22, 3) list in metres,
  "licence_tag", "resets", "help", "length_source", "queued_s", "generate_s", "files": {"npz", "bvh",
  "view"}}``. ``help``: the outside help P gave the motion (:func:`physmotion.metrics.report.help_stats`:
  root residual, share of frames at its cap, share over a joint's torque limit); {} without P.
  ``seconds`` null (or left out, unless ``ServeConfig.seconds`` is set): the length is predicted from the
  text (``length_source`` "predicted"). The same request gives the same joints as ``physmotion generate``
  with the same options and model.
- ``GET /api/motions/{id}.npz`` and ``.bvh``: the motion's files, named after the prompt in UTF-8 (RFC 6266
  ``filename*``, with an ASCII ``filename``); ``GET /motions/{id}``: its viewer page. The last
  ``ServeConfig.keep`` motions are kept.
- ``GET /api/health``: ``{"status": "ok", "model", "busy", "waiting"}`` (busy: a motion is being made;
  waiting: requests waiting behind it whose clients are still there).
"""

from __future__ import annotations

import asyncio
import functools
import itertools
import re
import socket
import tempfile
import threading
import time
import unicodedata
from collections import OrderedDict
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import asynccontextmanager
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any
from urllib.parse import quote

import numpy as np
from fastapi import FastAPI
from fastapi.exceptions import RequestValidationError
from fastapi.responses import HTMLResponse, JSONResponse, Response
from pydantic import BaseModel, ConfigDict, Field
from starlette.datastructures import Headers
from starlette.exceptions import HTTPException
from starlette.middleware.trustedhost import TrustedHostMiddleware
from starlette.requests import Request
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from physmotion.conventions import FPS, MIN_FRAMES
from physmotion.errors import PhysmotionError
from physmotion.metrics.report import help_stats
from physmotion.motion import Motion

if TYPE_CHECKING:
    from physmotion.diffusion.model import MotionDiffusion

# The physics modes the page offers (the API takes any spelling `generate --physics` takes).
PAGE_MODES = ("none", "none+floor", "post:1", "physdiff", "morph")
_WARMUP_TEXT = "a person walks forward"
# /assets/NAME -> the file of physmotion/viewer/ that the served viewer pages link instead of inlining
_ASSETS = {"three-bundle.min.js": "vendor/three-bundle.min.js", "viewer.js": "viewer.js"}
# Host header names always answered (with any port): this machine's own
LOCAL_HOSTS = ("localhost", "127.0.0.1", "[::1]")
_ANY_ADDRESS = ("", "0.0.0.0", "::")  # bound to every interface: no one name of the server
_DISCONNECT_POLL_S = 0.25  # how often a request waiting for its motion checks that its client is still there


@dataclass
class ServeConfig:
    """Options of a served app. ``physics`` and ``seconds`` are the defaults of a request (and the page's
    first choice; ``seconds`` None: each motion's length is predicted from its text); ``waiting``: requests
    that may wait behind the running one before 503; ``keep``: motions kept for download; ``steps``:
    sampling steps (None: the model's); ``max_projections``: a request whose physics mode runs P more often
    is refused (``post:50`` would hold the worker for minutes); ``max_body``: bytes of a request body, past
    which it is refused with 413 unread; ``host``: the address the server is bound to; ``allowed_hosts``:
    Host header names answered besides ``LOCAL_HOSTS`` and ``host`` ("*": any); ``warmup``: make one
    short motion at startup."""

    physics: str = "physdiff"  # generate's default: a served motion is `physmotion generate`'s
    seconds: float | None = None  # generate's default too: the length predicted from the text
    steps: int | None = None  # sampling steps; None: the model's sampler's (as `generate --steps`)
    waiting: int = 4
    keep: int = 32
    max_text: int = 500
    max_body: int = 16 * 1024  # 500 characters of text are at most 2 KB of UTF-8 JSON; room for the rest
    max_projections: int = 8
    host: str = "127.0.0.1"
    allowed_hosts: tuple[str, ...] = ()
    warmup: bool = True

    def __post_init__(self) -> None:
        allowed_hosts(self)  # a name TrustedHostMiddleware cannot match is refused here, before any socket


class GenerateRequest(BaseModel):
    """The JSON body of POST /api/generate; physics and seconds left out take ServeConfig's (seconds
    null: predicted from the text)."""

    model_config = ConfigDict(extra="forbid")
    text: str
    physics: str | None = None
    seconds: Annotated[float, Field(allow_inf_nan=False)] | None = None
    seed: int = Field(default=0, ge=0, le=2**32 - 1)


@dataclass
class _Served:
    """One generated motion and the request that made it."""

    motion: Motion
    request: dict[str, Any]
    length_source: str
    queued_s: float
    generate_s: float


class _Abandoned(Exception):
    """Raised in the worker thread at the next step of a motion whose client went away."""


@dataclass
class _Job:
    """One admitted request: ``started`` once the worker thread runs it; ``abandoned`` once its client went
    away (it then holds no place, and stops at its next sampling step or P run)."""

    future: Future | None = None
    started: bool = False
    abandoned: bool = False


@dataclass
class _Worker:
    """One thread runs the model; ``limit`` requests at most are running or waiting (the rest: 503). An
    abandoned request holds no place: one not started is cancelled, a running one stops at its next step."""

    limit: int
    executor: ThreadPoolExecutor = field(
        default_factory=lambda: ThreadPoolExecutor(max_workers=1, thread_name_prefix="physmotion-serve"))
    jobs: list[_Job] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def submit(self, fn: Callable[[_Job], Any]) -> _Job | None:
        """``fn(job)`` queued for the worker thread, or None where ``limit`` requests already hold a place."""
        with self.lock:
            if sum(not j.abandoned for j in self.jobs) >= self.limit:
                return None
            job = _Job()
            self.jobs.append(job)
        job.future = self.executor.submit(self._call, fn, job)
        job.future.add_done_callback(lambda _: self._drop(job))
        return job

    def _call(self, fn: Callable[[_Job], Any], job: _Job) -> Any:
        with self.lock:
            if job.abandoned:  # went away between cancel() failing and now: nothing to make
                raise _Abandoned
            job.started = True
        return fn(job)

    def _drop(self, job: _Job) -> None:
        with self.lock:
            self.jobs.remove(job)

    def abandon(self, job: _Job) -> None:
        """Free the place of a request whose client went away (cancel() runs the done callback, which takes
        the lock: so it is called outside it)."""
        with self.lock:
            job.abandoned = True
        job.future.cancel()

    def busy(self) -> bool:
        """A motion is being made (for a client or one that went away and has not reached its next step)."""
        with self.lock:
            return any(j.started for j in self.jobs)

    def waiting(self) -> int:
        """Requests waiting for the thread whose clients are still there."""
        with self.lock:
            return sum(not j.started and not j.abandoned for j in self.jobs)


class _HostCheck:
    """A request whose Host header is not a name of this server gets 400 ``{"error": ...}``: a page of
    another site whose name is made to resolve to 127.0.0.1 (DNS rebinding) reaches the server only under
    that site's name. Starlette's TrustedHostMiddleware decides (host without port, "*" allows any); this
    only puts its refusal, plain text there, in the app's JSON form."""

    def __init__(self, app: ASGIApp, hosts: list[str]) -> None:
        self.app = app
        self.hosts = hosts

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        passed = False

        async def through(scope_: Scope, receive_: Receive, _send: Send) -> None:
            nonlocal passed
            passed = True
            await self.app(scope_, receive_, send)

        async def dropped(_message: Message) -> None:
            return None

        await TrustedHostMiddleware(through, self.hosts, www_redirect=False)(scope, receive, dropped)
        if passed:
            return
        if scope["type"] == "http":
            host = Headers(scope=scope).get("host", "")
            await _error(400, f"Host {host!r} is not a name of this server (it answers {', '.join(self.hosts)}, "
                         "any port); `serve --allow-host NAME` adds one")(scope, receive, send)  # fmt: skip
        elif scope["type"] == "websocket":
            await send({"type": "websocket.close", "code": 1008})


class _BodyLimit:
    """413 ``{"error": ...}`` for a request body over ``limit`` bytes, before the app parses it. A
    Content-Length over the limit is refused unread; a body without one (chunked) is counted as it arrives
    and refused as soon as it passes the limit. A body within it is held (at most ``limit`` bytes) and handed
    to the app in one message; later receive() calls go to the server (they report a disconnect)."""

    def __init__(self, app: ASGIApp, limit: int) -> None:
        self.app = app
        self.limit = limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        length = Headers(scope=scope).get("content-length", "")
        if length.isdigit() and int(length) > self.limit:
            await self._refuse(int(length), scope, receive, send)
            return
        body = bytearray()
        while True:
            message = await receive()
            if message["type"] != "http.request":  # the client went away before its body was complete
                return
            body += message.get("body", b"")
            if len(body) > self.limit:
                await self._refuse(None, scope, receive, send)
                return
            if not message.get("more_body", False):
                break
        replayed = False

        async def replay() -> Message:
            nonlocal replayed
            if replayed:
                return await receive()
            replayed = True
            return {"type": "http.request", "body": bytes(body), "more_body": False}

        await self.app(scope, replay, send)

    async def _refuse(self, length: int | None, scope: Scope, receive: Receive, send: Send) -> None:
        size = f"is {length} bytes" if length is not None else "is over the limit"
        await _error(413, f"the request body {size}; this server takes at most {self.limit} bytes "
                     "(a prompt of at most a few hundred characters)")(scope, receive, send)  # fmt: skip


def allowed_hosts(cfg: ServeConfig) -> list[str]:
    """The Host header names (no port; IPv6 in brackets) a server with ``cfg`` answers: ``LOCAL_HOSTS``, the
    bound address unless it is every interface's (0.0.0.0, ::), and ``cfg.allowed_hosts``; PhysmotionError
    for a name TrustedHostMiddleware cannot match (a '*' anywhere but a leading '*.')."""
    names = [*LOCAL_HOSTS, *([] if cfg.host in _ANY_ADDRESS else [cfg.host]), *cfg.allowed_hosts]
    hosts: list[str] = []
    for name in names:
        host = name.strip().lower()
        if ":" in host and not host.startswith("["):
            host = f"[{host}]"
        if not host or ("*" in host and host != "*" and not (host.startswith("*.") and "*" not in host[1:])):
            raise PhysmotionError(f"allowed host {name!r} is not a host name: give a name or address without "
                                  "port, '*.example.org' for its subdomains, or '*' for any")  # fmt: skip
        if host not in hosts:
            hosts.append(host)
    return hosts


def _error(status: int, message: str, headers: dict[str, str] | None = None) -> JSONResponse:
    """A JSON error answer: ``{"error": message}`` on one line."""
    return JSONResponse({"error": " ".join(message.split())}, status_code=status, headers=headers)


def _validation_message(errors: list[dict]) -> str:
    """One line for pydantic's errors of a request body: the first error, where and what."""
    first = errors[0] if errors else {}
    if first.get("type") == "json_invalid":
        return f"the body is not valid JSON ({first.get('ctx', {}).get('error', 'decode error')})"
    loc = [str(p) for p in first.get("loc", ()) if p != "body"]
    where = ".".join(loc) or "body"
    if first.get("type") == "missing":
        what = f"{where} is missing" if loc else "no JSON body"
        return f"{what}: send JSON such as {{\"text\": \"a person walks forward\"}}"
    return f"{where}: {first.get('msg', 'invalid')}"


def make_app(model: MotionDiffusion | str | Path | None = None, config: ServeConfig | None = None,
             log: Callable[[str], None] | None = None) -> FastAPI:  # fmt: skip
    """The served app (a FastAPI instance) around one warm model.

    model: a loaded ``MotionDiffusion``, a model folder, or None (the shipped default model).
    log: called with one line per generated motion and at startup (None: silent).
    """
    from physmotion.diffusion.model import MotionDiffusion
    from physmotion.diffusion.samplers import default_sampler
    from physmotion.generate import GenerateConfig, generate

    cfg = config or ServeConfig()
    hosts = allowed_hosts(cfg)
    say = log or (lambda _: None)
    started = time.perf_counter()
    net = model if isinstance(model, MotionDiffusion) else MotionDiffusion.load(model)
    name = "default" if model is None else str(model) if isinstance(model, (str, Path)) else "in-process"
    sampler = default_sampler(net) if cfg.steps is None else replace(default_sampler(net), steps=cfg.steps)
    sampler.check()
    lo, hi = MIN_FRAMES / FPS, net.denoiser.max_frames / FPS
    if cfg.seconds is not None and not lo <= cfg.seconds <= hi:
        raise PhysmotionError(f"seconds must be between {lo:g} and {hi:g} (the model's range), got {cfg.seconds:g}")
    worker = _Worker(limit=1 + max(cfg.waiting, 0))
    motions: OrderedDict[str, _Served] = OrderedDict()
    ids = itertools.count(1)

    def check(req: GenerateRequest) -> GenerateConfig:
        """The request's GenerateConfig; PhysmotionError for what generate would refuse or the server
        does not run (too many projections)."""
        if not req.text.strip():
            raise PhysmotionError("text is empty: describe a motion, e.g. 'a person walks forward'")
        if len(req.text) > cfg.max_text:
            raise PhysmotionError(f"text is {len(req.text)} characters long; this server takes at most {cfg.max_text}")
        seconds = req.seconds if "seconds" in req.model_fields_set else cfg.seconds
        if seconds is not None and not lo <= seconds <= hi:
            raise PhysmotionError(f"seconds must be between {lo:g} and {hi:g} (the model's range), got {seconds:g}")
        physics = cfg.physics if req.physics is None else req.physics
        gen = GenerateConfig(seconds=seconds, physics=physics, seed=req.seed, sampler=replace(sampler))
        runs = len(gen.physics.hook_steps(sampler.steps)) + gen.physics.projections
        if runs > cfg.max_projections:
            raise PhysmotionError(f"physics {physics!r} runs the simulation {runs} times; this server "
                                  f"runs at most {cfg.max_projections} per request")  # fmt: skip
        return gen

    def run(req: GenerateRequest, gen: GenerateConfig, queued: float, job: _Job) -> _Served:
        def stop_if_abandoned(_done: int, _total: int) -> None:  # called after each sampling step and P run
            if job.abandoned:
                raise _Abandoned

        start = time.perf_counter()
        result = generate([req.text], gen, net, on_step=stop_if_abandoned)
        served = _Served(motion=result.motions[0], request=req.model_dump(),
                         length_source=(result.length_source or ["given"])[0],
                         queued_s=start - queued, generate_s=time.perf_counter() - start)  # fmt: skip
        served.request["physics"] = str(gen.physics)
        return served

    def keep(served: _Served) -> str:
        mid = f"m{next(ids)}"
        motions[mid] = served
        while len(motions) > max(cfg.keep, 1):
            motions.popitem(last=False)
        return mid

    def find(mid: str) -> _Served:  # one read: another thread may drop the oldest motion meanwhile
        served = motions.get(mid)
        if served is None:
            raise HTTPException(404, f"no motion {mid!r}: this server keeps its last {cfg.keep} motions")
        return served

    if cfg.warmup:  # the text encoder, torch's kernels and the prompt cache, before the first user
        generate([_WARMUP_TEXT], GenerateConfig(seconds=lo, physics="none", sampler=sampler), net)
    say(f"model {name} loaded and warm in {time.perf_counter() - started:.1f} s")

    @asynccontextmanager
    async def lifespan(_app: FastAPI):
        yield
        worker.executor.shutdown(wait=False, cancel_futures=True)

    app = FastAPI(title="physmotion serve", lifespan=lifespan, docs_url=None, redoc_url=None, openapi_url=None)
    app.state.model = net
    app.state.config = cfg
    # the last added runs first: a foreign Host is refused before its body is read
    app.add_middleware(_BodyLimit, limit=cfg.max_body)
    app.add_middleware(_HostCheck, hosts=hosts)

    @app.exception_handler(RequestValidationError)
    async def _invalid(_request, exc: RequestValidationError):
        return _error(422, _validation_message(list(exc.errors())))

    @app.exception_handler(HTTPException)
    async def _http(_request, exc: HTTPException):
        return _error(exc.status_code, str(exc.detail))

    @app.exception_handler(PhysmotionError)
    async def _refused(_request, exc: PhysmotionError):
        return _error(400, str(exc))

    @app.get("/", response_class=HTMLResponse)
    def page() -> HTMLResponse:
        return HTMLResponse(_page(cfg, lo, hi))

    @app.get("/api/health")
    def health() -> dict:
        return {"status": "ok", "model": name, "busy": worker.busy(), "waiting": worker.waiting()}

    @app.post("/api/generate")
    async def generate_route(req: GenerateRequest, request: Request) -> JSONResponse:
        gen = check(req)
        queued = time.perf_counter()
        job = worker.submit(lambda job: run(req, gen, queued, job))
        if job is None:
            return _error(503, f"busy: one motion is being made and {worker.limit - 1} wait; try again in a "
                          "moment", headers={"Retry-After": "1"})  # fmt: skip
        done = asyncio.wrap_future(job.future)
        while not done.done():  # the server tells a request its client went away only when it asks
            await asyncio.wait({done}, timeout=_DISCONNECT_POLL_S)
            if not done.done() and await request.is_disconnected():
                worker.abandon(job)
                done.add_done_callback(lambda f: f.cancelled() or f.exception())  # _Abandoned: not an error
                say(f"{req.text.strip()!r}: the client went away; " +
                    ("stopped at its next step" if job.started else "dropped before it started"))  # fmt: skip
                return _error(499, "the client closed the request")  # nginx's code; no one reads it
        try:
            served = done.result()
        except PhysmotionError as exc:
            return _error(400, str(exc))
        except Exception as exc:  # noqa: BLE001 - the server stays up and the request is answered
            return _error(500, f"generation failed: {type(exc).__name__}: {exc}")
        mid = keep(served)
        say(f"{mid}: {req.text.strip()!r} ({served.request['physics']}, {served.motion.num_frames / FPS:g} s, "
            f"seed {req.seed}) in {served.generate_s:.2f} s")  # fmt: skip
        return JSONResponse(_answer(mid, served))

    @app.get("/api/motions/{mid}.npz")
    def download_npz(mid: str) -> Response:
        return _download(find(mid), ".npz", mid)

    @app.get("/api/motions/{mid}.bvh")
    def download_bvh(mid: str) -> Response:
        return _download(find(mid), ".bvh", mid)

    @app.get("/motions/{mid}", response_class=HTMLResponse)
    def view(mid: str) -> HTMLResponse:
        from physmotion.render import make_tracks
        from physmotion.viewer import view_html

        served = find(mid)
        tracks, fps = make_tracks([served.motion], [served.motion.texts[0]])
        return HTMLResponse(_linked(view_html(tracks, fps, title=served.motion.texts[0])))

    @app.get("/assets/{name}")
    def asset(name: str) -> Response:
        if name not in _ASSETS:
            raise HTTPException(404, f"no asset {name!r}")
        return Response(_viewer_asset(_ASSETS[name]), media_type="text/javascript; charset=utf-8",
                        headers={"Cache-Control": "max-age=86400, immutable"})

    return app


@functools.cache
def _viewer_asset(name: str) -> str:
    """A file of physmotion/viewer/ (its script, the vendored three.js) as text."""
    return resources.files("physmotion.viewer").joinpath(name).read_text(encoding="utf-8")


def _linked(page: str) -> str:
    """A viewer page (``physmotion view``'s, scripts inlined) with its scripts linked from /assets/ instead:
    the browser keeps them and their compiled code between motions, so only the motion's data is new.
    A script that is not found verbatim stays inlined."""
    for url, name in _ASSETS.items():
        page = page.replace(f"<script>{_viewer_asset(name)}</script>", f'<script src="/assets/{url}"></script>', 1)
    return page


def _answer(mid: str, served: _Served) -> dict[str, Any]:
    """The JSON answer of POST /api/generate (joints rounded to 0.1 mm)."""
    motion = served.motion
    return {
        "id": mid,
        **served.request,
        "seconds": round(motion.num_frames / motion.fps, 3),
        "fps": float(motion.fps),
        "frames": int(motion.num_frames),
        "joints": np.round(motion.joints, 4).tolist(),
        "licence_tag": motion.licence_tag,
        "resets": motion.resets,
        "help": help_stats([motion]),
        "length_source": served.length_source,
        "queued_s": round(served.queued_s, 3),
        "generate_s": round(served.generate_s, 3),
        "files": {"npz": f"/api/motions/{mid}.npz", "bvh": f"/api/motions/{mid}.bvh", "view": f"/motions/{mid}"},
    }


def _download(served: _Served, suffix: str, mid: str) -> Response:
    """The motion as an .npz or .bvh attachment named after its text and seed."""
    from physmotion.generate import slug
    from physmotion.io.export import save_bvh

    with tempfile.TemporaryDirectory(prefix="physmotion-serve-") as tmp:
        path = Path(tmp) / f"motion{suffix}"
        if suffix == ".npz":
            served.motion.save(path)
        else:
            save_bvh(served.motion, path)
        payload = path.read_bytes()
    stem, tail = slug(served.motion.texts[0]), f"_s{served.request['seed']}_{mid}{suffix}"
    kind = "application/octet-stream" if suffix == ".npz" else "text/plain; charset=utf-8"
    return Response(payload, media_type=kind, headers={"Content-Disposition": _attachment(stem, tail)})


def _attachment(stem: str, tail: str) -> str:
    """A Content-Disposition header for the file ``stem + tail`` (``tail`` ASCII), per RFC 6266 section 4.3:
    ``filename`` in ASCII for clients that know no more, and where the name is not ASCII, ``filename*`` in
    UTF-8, percent-encoded (RFC 8187, which replaced RFC 5987), which browsers prefer. Header values go out
    as Latin-1, so a Cyrillic or CJK name in ``filename`` alone fails (a 500)."""
    name = stem + tail
    folded = unicodedata.normalize("NFKD", stem).encode("ascii", "ignore").decode()
    fallback = (re.sub(r"[^A-Za-z0-9_-]+", "_", folded).strip("_") or "motion") + tail
    header = f'attachment; filename="{fallback}"'
    if fallback != name:
        header += f"; filename*=UTF-8''{quote(name, safe='')}"
    return header


def _page(cfg: ServeConfig, lo: float, hi: float) -> str:
    """The app's page with its defaults filled in."""
    import html

    modes = list(PAGE_MODES) + ([cfg.physics] if cfg.physics not in PAGE_MODES else [])
    options = "".join(f'<option value="{html.escape(m)}"{" selected" if m == cfg.physics else ""}>'
                      f"{html.escape(m)}</option>" for m in modes)  # fmt: skip
    parts = {"OPTIONS": options, "SECONDS": "" if cfg.seconds is None else f"{cfg.seconds:g}",
             "RANGE": f"{lo:g} to {hi:g} s"}
    text = resources.files(__package__).joinpath("page.html").read_text(encoding="utf-8")
    return re.sub(r"\{\{([A-Z]+)\}\}", lambda m: parts[m.group(1)], text)


def check_physics(spec: str) -> str:
    """The canonical spelling of a physics mode; PhysmotionError for one generate does not know."""
    from physmotion.generate import GenerateConfig

    return str(GenerateConfig(physics=spec).physics)


def bind(host: str, port: int) -> socket.socket:
    """A listening TCP socket on ``host``:``port`` (0: any free port); PhysmotionError if it is taken."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise PhysmotionError(f"cannot listen on {host}:{port} ({exc.strerror}); choose another --port") from None
    sock.listen(128)
    return sock


def serve(app: Any, sock: socket.socket, log_level: str = "warning") -> None:
    """Run ``app`` under uvicorn on the bound socket ``sock`` until interrupted (Ctrl-C)."""
    import uvicorn

    server = uvicorn.Server(uvicorn.Config(app, log_level=log_level, timeout_graceful_shutdown=2))
    server.run(sockets=[sock])


def url_of(sock: socket.socket) -> str:
    """The http:// address a browser opens for a bound socket."""
    host, port = sock.getsockname()[:2]
    return f"http://{f'[{host}]' if ':' in host else host}:{port}/"


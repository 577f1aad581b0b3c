"""``physmotion serve``: the local web app over a warm model (physmotion.serve)."""

from __future__ import annotations

from pathlib import Path

import typer

from physmotion.cli._common import MODEL_HELP, _model_dir, _warn, app, console
from physmotion.errors import PhysmotionError

@app.command("serve")
def serve_cmd(
    host: str = typer.Option("127.0.0.1", help="Address to listen on; only this machine reaches 127.0.0.1."),
    port: int = typer.Option(8000, help="Port to listen on (0: any free port; the address is printed)."),
    model: Path | None = typer.Option(None, help=MODEL_HELP),
    physics: str = typer.Option("physdiff", help="The page's and the JSON endpoint's default physics mode "
                                "(any of generate's; a request may name another)."),
    seconds: float | None = typer.Option(None, help="The page's and the JSON endpoint's default length in "
                                         "seconds (default: predicted from each prompt; a request may give "
                                         "its own)."),
    allow_host: list[str] = typer.Option([], "--allow-host", help="A Host name (or address) to answer besides "
                                         "localhost, 127.0.0.1, [::1] and --host, e.g. this machine's name on "
                                         "the network when --host is 0.0.0.0; '*.example.org' for its "
                                         "subdomains, '*' for any (no DNS rebinding guard). Repeatable."),
    waiting: int = typer.Option(4, help="Requests that may wait behind the one being generated; past that the "
                                "server answers 503 (busy) at once."),
    steps: int | None = typer.Option(None, help="Sampling steps, as generate's --steps: fewer answer sooner "
                                     "(default: the model's sampler's, 10 DPM-Solver++ steps for the shipped "
                                     "models)."),
) -> None:
    """A local web app that keeps the model warm: type a prompt, watch the motion, download it; and a JSON
    endpoint for scripts (POST /api/generate)."""
    try:
        from physmotion.serve import ServeConfig, bind, check_physics, make_app, serve, url_of
    except ImportError as exc:
        raise PhysmotionError(f"physmotion serve needs the 'serve' extra ({exc.name} is missing): "
                              "pip install 'physmotion[serve]'") from None
    check_physics(physics)
    config = ServeConfig(physics=physics, seconds=seconds, waiting=waiting, steps=steps, host=host,
                         allowed_hosts=tuple(allow_host))  # fmt: skip
    sock = bind(host, port)
    app_ = make_app(_model_dir(model), config,
                    log=lambda line: console.print(line, highlight=False))
    if host not in ("127.0.0.1", "localhost", "::1"):
        _warn(f"listening on {host}: other machines can reach this server")
    console.print(f"serving on {url_of(sock)} (Ctrl-C stops)", highlight=False)
    serve(app_, sock)

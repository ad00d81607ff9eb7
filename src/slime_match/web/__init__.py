"""``slime web``: a local web app to match two images and look at the matches, at Slime's stages and at the
pairs of a ``slime pairs`` run, and to annotate ground-truth correspondences in the formats ``slime bench``
reads. Needs the ``web`` extra (FastAPI and uvicorn)."""

from __future__ import annotations

import ipaddress
import os

from ..errors import SlimeMatchError


def is_loopback(host: str) -> bool:
    """Whether ``host`` (a name or an address) is this machine only."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def serve(host: str = "127.0.0.1", port: int = 8000, images: list[str | os.PathLike] = (),
          runs: list[str | os.PathLike] = (), annotations: str | os.PathLike | None = None,
          max_upload_mb: float | None = None, max_megapixels: float | None = None) -> None:
    """Run the app with uvicorn until Ctrl-C (see :func:`slime_match.web.app.create_app`)."""
    try:
        import uvicorn

        from .app import LOOPBACK_HOSTS, MAX_UPLOAD_MB, create_app
        from .image_checks import MAX_IMAGE_PIXELS
    except ImportError as error:
        raise SlimeMatchError(f"slime web needs FastAPI and uvicorn ({error.name} is missing): "
                              "pip install 'slime-match[web]'") from None
    loopback = is_loopback(host)
    app = create_app(images, runs, annotations, MAX_UPLOAD_MB if max_upload_mb is None else max_upload_mb,
                     allowed_hosts=LOOPBACK_HOSTS if loopback else None,
                     max_megapixels=MAX_IMAGE_PIXELS / 1e6 if max_megapixels is None else max_megapixels)
    if not loopback:
        print(f"warning: listening on {host}: any machine that reaches it can read the served folders and run "
              "matches (there is no login); use 127.0.0.1 unless the network is yours")
    shown = f"[{host}]" if ":" in host else host
    print(f"slime web: http://{shown}:{port}/ (Ctrl-C stops it)")
    uvicorn.run(app, host=host, port=port, log_level="warning")

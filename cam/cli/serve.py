"""``cam serve``: the web page that controls the machine (needs the ``cam[web]`` extra)."""
from __future__ import annotations

import argparse
import importlib.util

from ..errors import CamError
from ..web.server import ServerConfig, is_loopback, new_token, serve
from .common import port_settings
from .machine_state import state_path_of

__all__ = ["cmd_serve", "missing_web_packages"]

_WEB_PACKAGES = {"starlette": ("starlette",), "uvicorn": ("uvicorn",),
                 "python-multipart": ("python_multipart", "multipart")}
"""Distribution of the web extra -> the module names it may install (python-multipart renamed its module)."""


def missing_web_packages() -> list[str]:
    """The distributions of the ``cam[web]`` extra that cannot be imported (found without importing them)."""
    return [dist for dist, modules in _WEB_PACKAGES.items()
            if not any(importlib.util.find_spec(m) is not None for m in modules)]


def cmd_serve(args: argparse.Namespace) -> int:
    missing = missing_web_packages()
    if missing:
        raise CamError(f"the web page needs {', '.join(missing)}: pip install 'cam[web]'")
    if not (0 <= args.http_port <= 65535):
        raise CamError(f"--http-port must be 0..65535, got {args.http_port}")
    if not (args.max_upload_mb > 0):
        raise CamError(f"--max-upload-mb must be > 0, got {args.max_upload_mb}")
    settings = port_settings(args, args.port)
    limits = {name: value for name, value in (
        ("max_connections", args.max_connections), ("max_event_streams", args.max_event_streams),
        ("header_timeout_s", args.header_timeout), ("body_timeout_s", args.body_timeout),
        ("work_time_limit_s", args.work_time_limit),
        ("work_memory_limit_bytes", None if args.work_memory_limit is None else int(args.work_memory_limit * 2**20)),
    ) if value is not None}  # the rest: ServerConfig's defaults
    token = args.token
    if token is None and not is_loopback(args.host):
        token = new_token()  # printed in the page's URL by serve()
    config = ServerConfig(host=args.host, port=args.http_port, token=token, jobs_dir=args.jobs_dir,
                          allowed_hosts=tuple(args.allow_host or ()),
                          max_upload_bytes=int(args.max_upload_mb * 1024 * 1024), settings=settings,
                          machine_port=args.port, realtime=args.realtime,
                          state_file=str(state_path_of(args)), machine_file=args.machine or "",
                          machine_changed=args.machine_changed, **limits)
    config.checked()
    return serve(config, announce=lambda line: print(line, flush=True))

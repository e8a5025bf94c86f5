"""``cam serve``: the web page that controls the machine."""
from __future__ import annotations

import argparse

from ..errors import CamError
from ..web.server import ServerConfig, serve
from .common import port_settings

__all__ = ["cmd_serve"]


def cmd_serve(args: argparse.Namespace) -> int:
    if not (0 <= args.port <= 65535):
        raise CamError(f"--port must be 0..65535, got {args.port}")
    if not (args.max_upload_mb > 0):
        raise CamError(f"--max-upload-mb must be > 0, got {args.max_upload_mb}")
    settings = port_settings(args, args.machine_port)
    config = ServerConfig(host=args.host, port=args.port, token=args.token, jobs_dir=args.jobs_dir,
                          max_upload_bytes=int(args.max_upload_mb * 1024 * 1024), settings=settings,
                          machine_port=args.machine_port, realtime=args.realtime)
    return serve(config, announce=lambda line: print(line, flush=True))

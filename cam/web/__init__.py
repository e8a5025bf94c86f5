"""The web page: full control of the machine from a phone or a desktop browser (``python -m cam serve``)."""
from ..drive.session import MachineSession
from .server import ServerConfig, create_app, serve

__all__ = ["MachineSession", "ServerConfig", "create_app", "serve"]

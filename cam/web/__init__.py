"""The web page: full control of the machine from a phone or a desktop browser (``python -m cam serve``)."""
from .server import MachineSession, ServerConfig, create_app, serve

__all__ = ["MachineSession", "ServerConfig", "create_app", "serve"]

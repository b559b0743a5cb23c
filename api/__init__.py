"""The semwm HTTP service (FastAPI): ``create_app(settings)`` and ``semwm serve``."""

from api.app import create_app
from api.settings import Settings

__all__ = ["Settings", "create_app"]

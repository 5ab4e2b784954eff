"""Scene files (TOML): schema, validation and loading."""

from .errors import SceneError
from .loader import SceneDescription, load_scene, parse_scene, read_toml

__all__ = ["SceneError", "SceneDescription", "load_scene", "parse_scene", "read_toml"]

"""Scene configuration: YAML scene files checked into typed dataclasses."""
from .load import config_from_dict, format_config_error, load_config
from .schema import ConfigError, SceneConfig

__all__ = ["ConfigError", "SceneConfig", "config_from_dict", "format_config_error", "load_config"]

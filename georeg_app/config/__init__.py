"""The TOML configuration files of ``georeg measure``, ``compare`` and ``track``, read and checked."""

from georeg_app.config.measure import (METHOD_NAMES, AUTO, integer_or_auto, lengths_or_auto,
                                       GEOMETRY_KINDS, NORMALISATIONS, DEFAULT_TIKHONOV_LENGTHS_MM,
                                       DEFAULT_OUTPUT_DIR, ImagesConfig, Landmark, CAMERA_SOURCES,
                                       CamerasConfig, GeometryConfig, MethodConfig, OutputConfig,
                                       Config, load_config)
from georeg_app.config.cad import AUTO_POSE, RoughPose, take_cad, cad_file
from georeg_app.config.roi import ROI_SURFACES, RoiConfig, take_roi
from georeg_app.config.toml_schema import (ConfigError, ConfigFileNotFoundError, Table, load_toml,
                                           show, show_key, show_path, integer, count, number,
                                           positive, boolean, string, table, table_list, one_of,
                                           strings, vector, array, numbers, pair, check,
                                           resolve_path, existing_file)
from georeg_app.config.track import (SeriesConfig, DisplacementConfig, ReferenceConfig, TrackConfig,
                                     load_track_config, natural_key, DISPLACEMENT_METHODS,
                                     REFERENCE_SUMMARY)

__all__ = ["METHOD_NAMES", "AUTO", "integer_or_auto", "lengths_or_auto", "GEOMETRY_KINDS",
           "NORMALISATIONS", "DEFAULT_TIKHONOV_LENGTHS_MM", "DEFAULT_OUTPUT_DIR", "ImagesConfig",
           "Landmark", "CAMERA_SOURCES", "CamerasConfig", "GeometryConfig", "MethodConfig",
           "OutputConfig", "Config", "load_config", "ConfigError", "ConfigFileNotFoundError",
           "Table", "load_toml", "show", "show_key", "show_path", "integer", "count", "number",
           "positive", "boolean", "string", "table", "table_list", "one_of", "strings", "vector",
           "array", "numbers", "pair", "check", "resolve_path", "existing_file", "SeriesConfig",
           "DisplacementConfig", "ReferenceConfig", "TrackConfig", "load_track_config",
           "natural_key", "DISPLACEMENT_METHODS", "REFERENCE_SUMMARY", "ROI_SURFACES", "RoiConfig",
           "take_roi", "AUTO_POSE", "RoughPose", "take_cad", "cad_file"]

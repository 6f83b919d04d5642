"""Machine models as files: MJCF numbers and values, error models (TOML, generated for any
MJCF), DH tables and URDF imported into MJCF (pkm-calib from-dh|from-urdf|error-model)."""

from common.face import face

__all__, __getattr__, __dir__ = face(
    __name__,
    {
        "dh_extract": (
            "dh_table_of",
            "format_dh_table",
        ),
        "dh_mjcf": (
            "build_xml",
            "exact",
        ),
        "dh_table": ("dh_table_command", "read_dh_table"),
        "error_model": ("error_model_command",),
        "from_urdf": ("from_urdf_command",),
        "mjcf_values": (
            "WrittenMjcf",
            "mjcf_with_values",
            "with_header",
        ),
        "parameter_file": (
            "closest",
            "load_parameter_set",
            "load_values",
            "read_utf8",
        ),
    },
)

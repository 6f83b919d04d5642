"""The ground floor, below twin: files written whole or not at all (atomic writes, sets of files
written as one), and the lazy package faces."""

from common.face import face

__all__, __getattr__, __dir__ = face(
    __name__,
    {
        "atomic_files": (
            "json_text",
            "plain_json",
            "write_bytes_atomic",
            "write_json_atomic",
            "write_text_atomic",
            "write_with_atomic",
        ),
        "write_set": (
            "WriteSetError",
            "staged",
            "write_files",
        ),
    },
)

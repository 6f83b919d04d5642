"""The ground floor, below twin: files written whole or not at all (atomic writes, sets of files
written as one), the lazy package faces, and independent tasks in worker processes."""

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
        "worker_processes": (
            "Progress",
            "WorkerLost",
            "map_chunks",
            "map_in_order",
            "shared_array",
            "worker_count",
        ),
        "write_set": (
            "WriteSetError",
            "staged",
            "write_files",
        ),
    },
)

"""Scenario files: TOML a user can copy and edit, checked at load against its study's keys
(keys, schema) with errors that name the key; found by name or path (scenario)."""

from common.face import face

__all__, __getattr__, __dir__ = face(
    __name__,
    {
        "effects": ("EFFECTS",),
        "keys": ("PLACEMENTS", "SCHEMAS"),
        "schema": ("Key", "ScenarioError", "Table", "_check_effects", "unknown_name_message"),
        "scenario": (
            "REPO_ROOT",
            "SCENARIO_DIR",
            "Scenario",
            "find_scenario",
            "load_scenario",
            "scenario_files",
            "search_places",
            "validate",
            "values_file_problems",
        ),
    },
)

"""The studies a scenario file can name (``study = ...``): each in its own folder with its
scenario files (TOML), its run (study.py), its report (report.py) and its figures."""

# study name -> (module with run(scenario, out_dir, progress), module with report(summary))
STUDIES = {
    "hexapod_paper": (
        "scenarios.studies.hexapod_paper.study",
        "scenarios.studies.hexapod_paper.report",
    ),
    "polisher_identifiability": (
        "scenarios.studies.polisher_identifiability.study",
        "scenarios.studies.polisher_identifiability.report",
    ),
    "liu_vs_ols": ("scenarios.studies.liu_vs_ols.study", "scenarios.studies.liu_vs_ols.report"),
    "liu_regime": ("scenarios.studies.liu_regime.study", "scenarios.studies.liu_regime.report"),
    "optimal_poses": (
        "scenarios.studies.optimal_poses.study",
        "scenarios.studies.optimal_poses.report",
    ),
    "undeclared_effect": (
        "scenarios.studies.undeclared_effect.study",
        "scenarios.studies.undeclared_effect.report",
    ),
    "serial_arm": ("scenarios.studies.serial_arm.study", "scenarios.studies.serial_arm.report"),
    "measured_loop": (
        "scenarios.studies.measured_loop.study",
        "scenarios.studies.measured_loop.report",
    ),
    "diagnosis_benchmark": (
        "scenarios.studies.diagnosis_benchmark.study",
        "scenarios.studies.diagnosis_benchmark.report",
    ),
    "iso9283": ("scenarios.studies.iso9283.study", "scenarios.studies.iso9283.report"),
}

__all__ = ["STUDIES"]

"""Speed benchmark (make bench): forward kinematics, identification against scipy, scenario
runtimes; results/bench.json and bench.md (python -m bench)."""

__all__: list[str] = []

"""The liu_regime study: Where the Liu estimator beats OLS: liu_vs_ols's plan and twin over tracker
noise and test
Its scenario files (TOML) beside its run (study.py), report and figures."""

__all__ = ["figures", "report", "study"]

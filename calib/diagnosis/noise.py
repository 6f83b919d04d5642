"""The noise level the residual is compared with: from repeats when the data has them.

A reading averaged over R repeats has a per-coordinate noise sigma / sqrt(R), with sigma the
pooled scatter of the repeats. A typed sigma is checked against that scatter and, after the
diagnosis, against the held-out residual floor; it never decides which effect is named (that
is the held-out error's job), so the verdict does not flip between plausible sigmas.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

PLAUSIBLE = (0.5, 2.0)  # a typed sigma outside this ratio to the repeats is flagged


@dataclass(frozen=True)
class NoiseLevel:
    sigma_m: float  # per coordinate, of the (repeat-averaged) readings the fit used
    source: str  # "repeats", "typed", "typed, checked against repeats"
    typed_m: float | None = None  # per coordinate of one reading, as typed
    repeats_m: float | None = None  # per coordinate of one reading, from the repeats
    n_repeats: int = 1
    notes: tuple[str, ...] = field(default=())

    def as_dict(self) -> dict:
        mm = lambda v: None if v is None else float(v) * 1e3  # noqa: E731
        return {
            "sigma_mm_per_coordinate": mm(self.sigma_m),
            "source": self.source,
            "typed_mm": mm(self.typed_m),
            "repeats_mm": mm(self.repeats_m),
            "n_repeats": self.n_repeats,
            "notes": list(self.notes),
        }


def noise_level(
    typed_m: float | None,
    repeat_std_m: np.ndarray | None = None,
    n_repeats: int = 1,
    typed_source: str = "typed",
) -> NoiseLevel:
    """The per-coordinate noise of the averaged readings, and what the repeats say of a typed
    sigma. ``repeat_std_m`` (P, T, 3) is the per-reading sample scatter over ``n_repeats``;
    ``typed_source`` names where a typed sigma came from ("assumed" when nothing gave one)."""
    rep = None
    if repeat_std_m is not None and n_repeats > 1:
        s = np.asarray(repeat_std_m, dtype=float)
        s = s[np.isfinite(s)]
        if s.size and np.any(s > 0):
            rep = float(np.sqrt(np.mean(s**2)))
    if rep is None and typed_m is None:
        raise ValueError("no noise level: give a tracker sigma or data with repeat readings")
    notes = []
    if rep is None:
        sigma = float(typed_m) / np.sqrt(n_repeats)
        return NoiseLevel(sigma, typed_source, typed_m, None, n_repeats)
    sigma = rep / np.sqrt(n_repeats)
    if typed_m is None:
        return NoiseLevel(sigma, "repeats", None, rep, n_repeats)
    ratio = typed_m / rep
    if not PLAUSIBLE[0] <= ratio <= PLAUSIBLE[1]:
        notes.append(
            f"the typed sigma {typed_m * 1e3:.4g} mm is {ratio:.2g} x the scatter of the "
            f"{n_repeats} repeats ({rep * 1e3:.4g} mm): the repeats are used"
        )
        return NoiseLevel(
            sigma, "repeats (typed sigma implausible)", typed_m, rep, n_repeats, tuple(notes)
        )
    # repeats catch only the short-term scatter: keep the (larger) typed value if plausible
    return NoiseLevel(
        max(typed_m, rep) / np.sqrt(n_repeats),
        "typed, checked against repeats",
        typed_m,
        rep,
        n_repeats,
    )


def chi_square_p(sum_sq: float, sigma_m: float, dof: int) -> float:
    # scipy.stats.chi2.sf is this function (without scipy.stats's 1 s import)
    from scipy import special

    return float(special.chdtrc(max(dof, 1), sum_sq / sigma_m**2))


def check_against_residual(noise: NoiseLevel, floor_m: float) -> tuple[str, ...]:
    """What the held-out residual floor (per coordinate) says of the noise level."""
    ratio = floor_m / noise.sigma_m
    if ratio < PLAUSIBLE[0]:
        return (
            f"the held-out residual ({floor_m * 1e3:.4g} mm per coordinate) is {ratio:.2g} x the "
            "noise level: the sigma is too large for this data",
        )
    return ()

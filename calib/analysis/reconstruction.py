"""The first paper's two reconstructions of a column-full-rank identification Jacobian (4.1).

Both work on the column-scaled H (unit column norms; zero columns stay zero):

* spectral: Z1 = H Phi with Phi the eigenvectors of H^T H whose eigenvalues are not zero;
  the new parameters are combinations of the source errors (no geometric meaning);
* correlation (Steps 1-3): start from H_xi (the encoder offsets), then append each column of
  H_eta in the declared order if it raises the rank by one. The result keeps the form
  [H_xi H_eta], so a coarse calibration of the encoder offsets stays possible. The order is
  fixed and the rank test uses one documented tolerance, so the selection is the same on
  every platform.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.analysis.identifiability import RANK_RTOL, scaled_jacobian
from calib.exceptions import IdentifiabilityError
from twin.kinematics.structure import on_one_blas_thread


@dataclass(frozen=True)
class SpectralReconstruction:
    phi: np.ndarray  # (n, m1) eigenvectors of the scaled H^T H with non-zero eigenvalues
    eigenvalues: np.ndarray  # (m1,) descending
    scale: np.ndarray  # column scale used

    @property
    def rank(self) -> int:
        return self.phi.shape[1]


def spectral_reconstruction(h: np.ndarray) -> SpectralReconstruction:
    """Eigenvectors of the scaled H^T H with non-zero eigenvalues (via the SVD of H)."""
    hs, scale, _ = scaled_jacobian(h)
    # the SVD of H resolves singular values to round-off of the largest; the eigenvalues of
    # H^T H only to round-off of its square, too coarse for the rank test
    _, sv, vt = np.linalg.svd(hs, full_matrices=False)
    keep = sv > RANK_RTOL * sv[0] if sv.size and sv[0] > 0 else np.zeros(0, bool)
    vec, lam = vt.T, sv**2
    return SpectralReconstruction(vec[:, keep], lam[keep], scale)


def _rank(a: np.ndarray, ref: float) -> int:
    if a.shape[1] == 0:
        return 0
    s = np.linalg.svd(a, compute_uv=False)
    return int(np.sum(s > RANK_RTOL * ref))


@on_one_blas_thread  # one SVD of a few hundred by at most m columns per column tried
def correlation_reconstruction(
    h: np.ndarray, names: tuple[str, ...] | list[str], xi: np.ndarray
) -> list[int]:
    """Indices kept by Steps 1-3 (H_xi first, then H_eta in order); raises if H_xi is deficient.

    ``xi`` is a boolean mask of the encoder-offset columns.
    """
    names = tuple(names)
    xi = np.asarray(xi, dtype=bool)
    hs, _, _ = scaled_jacobian(h)
    ref = float(np.linalg.norm(hs, 2)) if hs.size else 0.0
    xi_idx = list(np.flatnonzero(xi))
    r_xi = _rank(hs[:, xi_idx], ref)
    if r_xi < len(xi_idx):
        raise IdentifiabilityError(
            f"the pose plan cannot separate the encoder offsets: H_xi has rank {r_xi} for "
            f"{len(xi_idx)} offsets ({[names[i] for i in xi_idx]}); use more nodes spread "
            "over more than one line, so that every actuator moves"
        )
    kept = list(xi_idx)
    rank = r_xi
    for j in np.flatnonzero(~xi):
        trial = [*kept, int(j)]
        r = _rank(hs[:, trial], ref)
        if r == rank + 1:
            kept, rank = trial, r
    return kept

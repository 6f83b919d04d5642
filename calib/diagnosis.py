"""Residual diagnosis after geometric calibration: is there more than noise, and what is it?

1. Noise test: the residual's sum of squares against the tracker noise (chi-square with
   n - p degrees of freedom, p the estimated geometric parameters).
2. Candidates: each physical effect acts on the actuators as offsets D(pose) theta with a few
   parameters theta (thermal growth over the sequence, ball-screw lead error, backlash by
   approach direction, compliance under the gravity load); its identification columns are
   J_act D, with J_act the targets' sensitivity to actuator offsets.
3. Selection: each candidate is fitted beside the geometric columns (linearised at the
   geometric estimate) and judged on held-out poses (k-fold cross-validation) and by BIC; the
   best is chosen only if the noise test fails, it lowers the held-out error and BIC prefers
   it. Otherwise the answer is "none": nothing is forced.

Only the readings the identification kept enter (``IdentificationResult.rejected`` lists the
gross outliers it left out): an outlier is not an effect.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from calib.identify import IdentificationResult, Observations
from calib.model import CalibrationModel
from twin.effects.gravity_compliance import GravityCompliance
from twin.kinematics import forward
from twin.parameters import Parameter, ParameterSet
from twin.sensitivity import target_jacobian

Regressor = Callable[[CalibrationModel, np.ndarray, np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Candidate:
    """An effect as actuator offsets: regressor(model, values, commands, order) -> (N, A, k)."""

    name: str
    parameters: tuple[str, ...]
    regressor: Regressor


def _thermal(model, values, commands, order):
    slide = model.nominal.actuator_is_slide
    return (commands * np.asarray(order, float)[:, None] * slide)[:, :, None]


def _backlash(model, values, commands, order):
    seq = np.argsort(order, kind="stable")
    home = model.nominal.home_qpos[model.nominal.actuator_qpos]
    prev = np.vstack([home, commands[seq][:-1]])
    direction = np.zeros_like(commands)
    direction[seq] = np.sign(commands[seq] - prev)
    a = commands.shape[1]
    return -direction[:, :, None] * np.eye(a)[None, :, :]


def _lead(pitch: float) -> Regressor:
    def regress(model, values, commands, order):
        a = commands.shape[1]
        phase = 2 * np.pi * commands / pitch
        eye = np.eye(a)[None, :, :]
        return np.concatenate(
            [np.sin(phase)[:, :, None] * eye, np.cos(phase)[:, :, None] * eye], axis=2
        )

    return regress


def _gravity(model, values, commands, order):
    mech = GravityCompliance().loaded(model.mechanism(values))
    eff = GravityCompliance()
    tau = np.array([eff.actuator_forces(mech, forward(mech, c).qpos) for c in commands])
    a = commands.shape[1]
    return -tau[:, :, None] * np.eye(a)[None, :, :]  # compliance per actuator (m/N)


GRAVITY_SKIPPED = (
    "gravity_compliance skipped: the model declares no masses (MuJoCo's bounded defaults), so "
    "its gravity loads would be invented"
)


def default_candidates(
    actuators: tuple[str, ...],
    pitches_m: tuple[float, ...] = (5e-3,),
    masses_defaulted: bool = False,
):
    """The library: thermal growth, backlash, lead error per pitch, gravity compliance (not
    on a model whose masses were defaulted)."""
    out = [
        Candidate("thermal_growth", ("growth_per_pose",), _thermal),
        Candidate("backlash", tuple(f"{a}.half_play" for a in actuators), _backlash),
    ]
    if not masses_defaulted:
        out.append(
            Candidate("gravity_compliance", tuple(f"{a}.compliance" for a in actuators), _gravity)
        )
    for p in pitches_m:
        names = tuple(f"{a}.lead_{c}" for c in ("sin", "cos") for a in actuators)
        out.append(Candidate(f"lead_error_{p * 1e3:g}mm", names, _lead(p)))
    return out


@dataclass(frozen=True)
class CandidateScore:
    name: str
    n_parameters: int
    heldout_rms_mm: float
    bic: float
    theta: np.ndarray  # effect parameters
    geometry: np.ndarray  # correction of the estimated geometric parameters (SI)


@dataclass(frozen=True)
class Diagnosis:
    residual_rms_mm: float
    noise_floor_rms_mm: float
    chi2_p_value: float
    excess: bool
    scores: dict[str, CandidateScore] = field(default_factory=dict)
    chosen: str = "none"
    reason: str = ""
    coefficients: dict[str, np.ndarray] = field(default_factory=dict)  # effect parameters
    structure: dict[str, float] = field(default_factory=dict)  # rank correlations
    geometry_correction: np.ndarray | None = None  # for the estimated geometric parameters
    notes: tuple[str, ...] = ()  # candidates skipped, and why


def actuator_jacobians(model: CalibrationModel, values: np.ndarray, qpos: np.ndarray):
    """Per pose, d(targets)/d(actuator offsets), (N, T*3, A)."""
    mech = model.mechanism(values)
    offsets = ParameterSet(
        [
            Parameter(f"offset.{n}", "joint_zero", mech.model.joint(int(j)).name)
            for n, j in zip(mech.actuator_names, mech.actuator_joints, strict=True)
        ],
        mech.model,
    )
    zero = np.zeros(len(offsets))
    return np.array([target_jacobian(mech, offsets, zero, q) for q in qpos])


def _split(theta: np.ndarray, sizes: list[int]) -> list[np.ndarray]:
    return np.split(theta, np.cumsum(sizes)[:-1]) if sizes else []


def _fit(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    scale = np.linalg.norm(x, axis=0)
    scale[scale == 0] = 1.0
    return np.linalg.lstsq(x / scale, y, rcond=None)[0] / scale


def _library(model: CalibrationModel) -> list[Candidate]:
    mech = model.nominal
    return default_candidates(mech.actuator_names, masses_defaulted=mech.masses_defaulted)


def diagnose(
    model: CalibrationModel,
    obs: Observations,
    result: IdentificationResult,
    sigma_m: float,
    order: np.ndarray | None = None,
    candidates: list[Candidate] | None = None,
    folds: int = 5,
    alpha: float = 0.01,
    min_gain: float = 0.1,
    tracker_position_m: np.ndarray | None = None,
) -> Diagnosis:
    """Diagnose the residual of a geometric calibration ``result`` on ``obs``.

    Only the readings the identification kept are used: those in ``result.rejected`` (gross
    outliers) weigh nothing in any fit or score, so an outlier is never read as an effect.

    With ``tracker_position_m`` (the head in the base frame, from the dataset's sidecar) the
    library also holds a scale error of the tracker: readings stretched about its head."""
    n_poses = len(obs.commands)
    order = np.arange(n_poses) if order is None else np.asarray(order)
    values = result.values
    pred = model.predict(values, obs.commands)
    keep = kept_rows(result, obs.measured.shape[:2])  # (N, T*3)
    r = (obs.measured - pred.targets).reshape(n_poses, -1) * keep  # (N, T*3)
    n = int(keep.sum())
    p = int(result.estimated.sum())
    chi2 = float(np.sum(r**2) / sigma_m**2)
    p_value = float(stats.chi2.sf(chi2, max(n - p, 1)))
    excess = p_value < alpha
    rows = keep[:, :, None]  # a rejected reading's rows are zero in every regressor
    geo = model.jacobian(values, pred)[:, result.estimated].reshape(n_poses, -1, p) * rows
    j_act = actuator_jacobians(model, values, pred.qpos)  # (N, T*3, A)
    blocks = {"none": np.zeros((n_poses, r.shape[1], 0))}
    for c in candidates or _library(model):
        d = c.regressor(model, values, obs.commands, order)  # (N, A, k)
        blocks[c.name] = np.einsum("nra,nak->nrk", j_act, d) * rows
    if tracker_position_m is not None:
        lever = pred.targets - np.asarray(tracker_position_m, dtype=float)  # (N, T, 3)
        blocks["tracker_scale"] = lever.reshape(n_poses, -1, 1) * rows
    fold_of = np.arange(n_poses) % folds

    def score(name: str, extra: list[np.ndarray]) -> CandidateScore:
        x = np.concatenate([geo, *extra], axis=2)  # (N, rows, p + k)
        sq = 0.0
        for f in range(folds):
            train, test = fold_of != f, fold_of == f
            coef = _fit(x[train].reshape(-1, x.shape[2]), r[train].reshape(-1))
            resid = r[test].reshape(-1) - x[test].reshape(-1, x.shape[2]) @ coef
            sq += float(np.sum(resid**2))
        coef = _fit(x.reshape(-1, x.shape[2]), r.reshape(-1))
        rss = float(np.sum((r.reshape(-1) - x.reshape(-1, x.shape[2]) @ coef) ** 2))
        k = x.shape[2] - p
        bic = n * np.log(rss / n) + (p + k) * np.log(n)
        return CandidateScore(name, k, float(np.sqrt(sq / n)) * 1e3, bic, coef[p:], coef[:p])

    rms = float(np.sqrt(np.sum(r**2) / n)) * 1e3
    scores = {name: score(name, [eff]) for name, eff in blocks.items()}
    common = dict(
        structure=residual_structure(r, pred.targets, obs.commands, order, keep),
        residual_rms_mm=rms,
        noise_floor_rms_mm=sigma_m * 1e3,
        chi2_p_value=p_value,
        excess=excess,
        scores=scores,
        notes=(GRAVITY_SKIPPED,) if candidates is None and model.nominal.masses_defaulted else (),
    )
    if not excess:
        return Diagnosis(**common, reason="the residual is what the tracker noise explains")
    # forward selection: add the effect that most lowers the held-out error, while it lowers
    # it by at least ``min_gain`` and BIC agrees; then try a second one beside the first
    chosen: list[str] = []
    current = scores["none"]
    while True:
        trials = [
            score("+".join([*chosen, name]), [blocks[c] for c in chosen] + [blocks[name]])
            for name in blocks
            if name != "none" and name not in chosen
        ]
        if not trials:
            break
        best = min(trials, key=lambda s: s.heldout_rms_mm)
        if best.heldout_rms_mm > (1 - min_gain) * current.heldout_rms_mm or best.bic >= current.bic:
            break
        chosen.append(best.name.split("+")[-1])
        current = best
    if not chosen:
        return Diagnosis(**common, reason="no candidate explains the excess on held-out poses")
    return Diagnosis(
        **common,
        chosen="+".join(chosen),
        reason=f"{' and '.join(chosen)} {'lower' if len(chosen) > 1 else 'lowers'} the held-out "
        "error from "
        f"{scores['none'].heldout_rms_mm:.4g} to {current.heldout_rms_mm:.4g} mm",
        geometry_correction=current.geometry,
        coefficients=dict(
            zip(chosen, _split(current.theta, [blocks[c].shape[2] for c in chosen]), strict=True)
        ),
    )


def effect_offsets(
    model: CalibrationModel,
    values: np.ndarray,
    commands: np.ndarray,
    order: np.ndarray,
    chosen: dict[str, np.ndarray],
    candidates: list[Candidate] | None = None,
) -> np.ndarray:
    """Actuator offsets (N, A) that the chosen effects predict for these commands."""
    library = {c.name: c for c in candidates or _library(model)}
    out = np.zeros_like(np.asarray(commands, dtype=float))
    for name, theta in chosen.items():
        out += np.einsum(
            "nak,k->na", library[name].regressor(model, values, commands, order), theta
        )
    return out


def kept_rows(result: IdentificationResult, shape: tuple[int, int]) -> np.ndarray:
    """(N, T*3) boolean: the residual rows of the readings ``result`` kept (not rejected)."""
    keep = np.ones(shape, dtype=bool)
    for rej in result.rejected:
        keep[rej.pose_index, rej.target_index] = False
    return np.repeat(keep, 3, axis=1)


def residual_structure(
    r: np.ndarray,
    targets: np.ndarray,
    commands: np.ndarray,
    order: np.ndarray,
    keep: np.ndarray | None = None,
) -> dict[str, float]:
    """Spearman rank correlation of each pose's residual size with where and when it was
    measured: tool position x, y, z (space), mean actuator value (actuator coordinates) and
    measurement order (time). Values near 0 mean no structure along that direction.

    ``keep`` (same shape as ``r``) marks the rows to use; a pose with none is left out."""
    keep = np.ones(r.shape, dtype=bool) if keep is None else np.asarray(keep, dtype=bool)
    count = keep.sum(axis=1)
    some = count > 0
    size = np.sqrt(np.sum(np.where(keep, r, 0.0) ** 2, axis=1)[some] / count[some])
    centre = targets.mean(axis=1)[some]
    commands = np.asarray(commands)[some]
    order = np.asarray(order)[some]
    probes = {
        "x": centre[:, 0],
        "y": centre[:, 1],
        "z": centre[:, 2],
        "mean_actuator": commands.mean(axis=1),
        "order": np.asarray(order, dtype=float),
    }
    out = {}
    for name, v in probes.items():
        rho = stats.spearmanr(size, v).statistic if np.ptp(v) > 0 else 0.0
        out[name] = float(np.nan_to_num(rho))
    return out

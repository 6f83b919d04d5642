"""The result of ``pkm-calib identify`` as a file a user can keep, read and use again.

JSON, millimetres and degrees, written atomically (0644). It carries what was estimated and
what was fixed (and why), standard errors, the strongest correlations, the tracker
registration when the readings were in the tracker's frame, the residual and the verdict.
``load_result`` reads it back for ``pkm-calib verify`` or a user's own script, and refuses a file
made for another model or another error model.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from calib.exceptions import CalibError
from calib.fit.prior import correlation_matrix
from calib.fit.registration import Registration, RegistrationError
from common.atomic_files import json_text, write_json_atomic

FORMAT = "pkm-calib-result"
VERSION = 1


class ResultFileError(CalibError):
    """A result file that is missing, malformed, or made for another model."""


@dataclass(frozen=True)
class CalibrationResult:
    """A result as read back: values in file units (mm, deg) by parameter name."""

    path: Path
    model: str
    names: tuple[str, ...]
    display_values: np.ndarray  # mm / deg, the order of ``names``
    estimated: np.ndarray  # bool
    registration: Registration | None
    data: dict[str, Any]

    def values_for(self, params: Any) -> np.ndarray:
        """SI values ordered as ``params`` (a twin ParameterSet); the names must match."""
        if tuple(params.names) != self.names:
            missing = sorted(set(params.names) - set(self.names))
            extra = sorted(set(self.names) - set(params.names))
            raise ResultFileError(
                f"{self.path}: the result's parameters do not match the error model "
                f"(missing from the result: {missing[:5]}, not in the error model: {extra[:5]})"
            )
        return np.asarray(params.from_display(self.display_values), dtype=float)


def correlation_pairs(
    names: tuple[str, ...], covariance: np.ndarray, threshold: float = 0.9
) -> list[dict[str, Any]]:
    """Pairs of estimated parameters whose correlation magnitude exceeds ``threshold``."""
    corr = correlation_matrix(covariance)
    out = []
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            if np.isfinite(corr[i, j]) and abs(corr[i, j]) > threshold:
                out.append({"a": names[i], "b": names[j], "r": float(corr[i, j])})
    return sorted(out, key=lambda p: -abs(p["r"]))


def result_text(content: dict[str, Any]) -> str:
    """The file's text: ``content`` (the keys of :func:`calib.cli.commands`'s identify) with
    format tags, as strict JSON."""
    return json_text({"format": FORMAT, "version": VERSION, **content})


def write_result(path: str | os.PathLike[str], content: dict[str, Any]) -> Path:
    """Write :func:`result_text` of ``content`` atomically."""
    return write_json_atomic(path, {"format": FORMAT, "version": VERSION, **content})


def unusable_values(loaded: CalibrationResult, params: Any, cause: Exception) -> ResultFileError:
    """The error for a result at whose values the model cannot be evaluated (``cause``, e.g.
    no closure): names the values beyond a plausible size, which are the likely reason."""
    from calib.fit.verdict import implausible_estimates

    odd = implausible_estimates(loaded.names, loaded.display_values, params.display_units())
    why = (
        f"; values beyond a plausible size: {', '.join(odd[:5])}"
        + (f" and {len(odd) - 5} more" if len(odd) > 5 else "")
        if odd
        else ""
    )
    return ResultFileError(
        f"{loaded.path}: the model with this result's values cannot be evaluated ({cause}){why}"
    )


def load_result(
    path: str | os.PathLike[str], expected_model: str | None = None
) -> CalibrationResult:
    """Read a result file; ``expected_model`` refuses a result of another machine."""
    p = Path(path)
    if not p.exists():
        raise ResultFileError(f"result file not found: {p}")
    if p.is_dir():
        raise ResultFileError(f"{p} is a folder, not a result file (identify --out R.json)")
    if not p.is_file():
        raise ResultFileError(
            f"{p} is not a regular file (a device, pipe or socket), not a result file "
            "(identify --out R.json)"
        )
    try:
        text = p.read_text(encoding="utf-8")
        if not text.strip():
            raise ResultFileError(f"{p} is empty, not a result file (identify --out R.json)")
        data = json.loads(text)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ResultFileError(f"{p} is not a result file (JSON, UTF-8): {exc}") from None
    return result_from_content(data, p, expected_model)


def result_from_content(data: Any, p: Path, expected_model: str | None = None) -> CalibrationResult:
    """:func:`load_result` of a result file's content ``data`` (JSON as read), named ``p``."""
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise ResultFileError(f"{p} is not a {FORMAT} file (no 'format': '{FORMAT}')")
    if data.get("version") != VERSION:
        raise ResultFileError(f"{p}: version {data.get('version')!r}, this tool reads {VERSION}")
    model = data.get("model")
    if expected_model is not None and model != expected_model:
        raise ResultFileError(
            f"{p} is a result for model '{model}', not for '{expected_model}' (another machine)"
        )
    params = data.get("parameters")
    if not isinstance(params, dict) or not params:
        raise ResultFileError(f"{p}: no 'parameters' table")
    names, values, est = [], [], []
    for name, entry in params.items():
        raw = entry.get("value") if isinstance(entry, dict) else None
        if isinstance(raw, bool) or not isinstance(raw, (int, float)):
            got = "none" if raw is None else f"{raw!r} ({type(raw).__name__})"
            raise ResultFileError(
                f"{p}: parameter '{name}' has no numeric 'value' (got {got}; a JSON number "
                "is expected, not a string)"
            )
        v = float(raw)
        if not np.isfinite(v):
            raise ResultFileError(f"{p}: parameter '{name}' value is not finite")
        names.append(name)
        values.append(v)
        est.append(entry.get("status", "estimated") == "estimated")
    reg = None
    if data.get("registration") is not None:
        try:
            reg = Registration.from_dict(data["registration"])
        except RegistrationError as exc:
            raise ResultFileError(f"{p}: {exc}") from None
    return CalibrationResult(
        path=p,
        model=str(model),
        names=tuple(names),
        display_values=np.array(values),
        estimated=np.array(est, dtype=bool),
        registration=reg,
        data=data,
    )

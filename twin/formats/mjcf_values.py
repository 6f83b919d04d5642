"""Parameter values written into the MJCF file itself: the user's file with its errors in it.

``mjcf_with_values`` returns the text of an MJCF file with the deviations of a ParameterSet
(``twin.parameters``) written into its geometry, exactly as injection applies them in memory:

* ``body_pos`` / ``body_rot``: the body's ``pos`` and ``quat`` (an ``euler``, ``axisangle``,
  ``xyaxes`` or ``zaxis`` it had is replaced by the equivalent ``quat``);
* ``site_pos``: the site's ``pos``;
* ``joint_zero``: the joint's ``ref`` (MuJoCo's ``qpos0``, the joint's zero), in the file's
  angle unit for a hinge;
* an actuator's gain ``g`` (``scales``: 1 + g per actuator name): the actuator's ``gear``
  1 / (1 + g), its joint's ``ref`` q0 (1 + g) (q0 the joint's zero), its joint's ``range`` and
  every keyframe's ``qpos`` of the joint times 1 + g. A command c then sets the joint to
  qpos = c / gear = c (1 + g) (a MuJoCo ``<position>`` servo settles where gear * qpos = c;
  twin.mechanism reads every command so), whose travel from the zero, qpos - ref, is
  (c - q0)(1 + g): the joint value q0 + (c - q0)(1 + g) the gain gives.

The file is patched, not regenerated: every other byte (comments, defaults, classes, the
order of attributes) stays as the user wrote it, and only elements whose geometry changes
are touched. Numbers are written with every digit (a round trip to the last bit), so the
compiled model equals the in-memory injection to round-off. An element placed inside a
``<frame>`` (or under a static body the compiler fuses) gets the local values that give the
same compiled pose. MuJoCo's own writer (``MjSpec.to_xml``) is not used: it keeps six
significant digits, a few micrometres on a metre.

Refused with an error naming the element: an element defined in an ``<include>``d file (it
is not in this text), a site given by ``fromto``, and a parameter kind this writer does not
know (a kind that is not geometry cannot be written into geometry).
"""

from __future__ import annotations

import os
import re
import xml.parsers.expat
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from twin.exceptions import ModelError
from twin.formats.mjcf_numbers import canonical_quat, snap
from twin.mechanism import BOUND_INERTIA, BOUND_MASS
from twin.parameters import HINGE, ParameterSet
from twin.rotations import matrix_from_quat, quat_multiply

WRITABLE_KINDS = ("body_pos", "body_rot", "site_pos", "joint_zero")
ACTUATOR_TAGS = ("general", "motor", "position", "velocity", "intvelocity", "damper", "cylinder")
ALT_ORIENTATIONS = ("quat", "axisangle", "euler", "xyaxes", "zaxis")
# attributes holding a path relative to the model file's folder (see _relocated)
_DIR_ATTRS = ("meshdir", "texturedir", "assetdir")
_FILE_TAGS = {"mesh": "meshdir", "skin": "meshdir", "hfield": "meshdir", "texture": "texturedir"}


class MjcfWriteError(ModelError):
    """Values that cannot be written into this MJCF file (the message names the element)."""


def exact(values) -> str:
    """Space-separated numbers with every digit (``repr``), tiny values written as 0."""
    out = []
    for x in np.atleast_1d(snap(values, 1e-15)).tolist():
        out.append(str(int(x)) if x == int(x) and abs(x) < 1e15 else repr(x))
    return " ".join(out)


@dataclass(frozen=True)
class _Tag:
    """One element's start tag: its name, attributes, where it lies in the file (bytes)."""

    tag: str
    attrs: dict[str, str]
    start: int
    end: int  # index of the closing '>'


@dataclass
class _Edit:
    set: dict[str, str] = field(default_factory=dict)
    remove: tuple[str, ...] = ()
    after: bytes = b""  # text put right after the start tag


def _tag_end(data: bytes, start: int) -> int:
    """Index of the '>' closing the start tag at ``start`` (quotes respected)."""
    quote = None
    for k in range(start + 1, len(data)):
        c = data[k : k + 1]
        if quote is not None:
            if c == quote:
                quote = None
        elif c in (b'"', b"'"):
            quote = c
        elif c == b">":
            return k
    raise MjcfWriteError("unterminated start tag in the MJCF text")


def _start_tags(data: bytes, where: str) -> list[_Tag]:
    """Every element's start tag, in the order of the file."""
    parser = xml.parsers.expat.ParserCreate()
    tags: list[_Tag] = []

    def start(tag: str, attrs: dict[str, str]) -> None:
        begin = parser.CurrentByteIndex
        tags.append(_Tag(tag, attrs, begin, _tag_end(data, begin)))

    parser.StartElementHandler = start
    try:
        parser.Parse(data, True)
    except xml.parsers.expat.ExpatError as exc:
        raise MjcfWriteError(f"{where} is not well-formed XML: {exc}") from None
    return tags


def _attr_pattern(name: str) -> re.Pattern[bytes]:
    return re.compile(rb"(\s)" + re.escape(name.encode()) + rb"""\s*=\s*("[^"]*"|'[^']*')""")


def _patched_tag(tag: bytes, edit: _Edit) -> bytes:
    for name in edit.remove:
        tag = _attr_pattern(name).sub(b"", tag)
    for name, value in edit.set.items():
        new = f'{name}="{value}"'.encode()
        pattern = _attr_pattern(name)
        if pattern.search(tag):
            tag = pattern.sub(lambda m, new=new: m.group(1) + new, tag, count=1)
        else:
            close = len(tag) - (2 if tag.endswith(b"/>") else 1)
            tag = tag[:close].rstrip() + b" " + new + tag[close:]
    return tag + edit.after


def _apply(data: bytes, edits: list[tuple[_Tag, _Edit]]) -> bytes:
    merged: dict[int, tuple[_Tag, _Edit]] = {}  # one edit per element
    for tag, edit in edits:
        if tag.start in merged:
            old = merged[tag.start][1]
            edit = _Edit({**old.set, **edit.set}, old.remove + edit.remove, old.after + edit.after)
        merged[tag.start] = (tag, edit)
    for start in sorted(merged, reverse=True):  # from the end: the offsets before stay valid
        tag, edit = merged[start]
        head, tail = data[: tag.start], data[tag.end + 1 :]
        data = head + _patched_tag(data[tag.start : tag.end + 1], edit) + tail
    return data


def _frame_of(spec: mujoco.MjSpec, kind: str, name: str) -> tuple[np.ndarray, np.ndarray] | None:
    """(quat, pos) of the frame an element's local values are given in, relative to its
    parent body, when that is not the parent body itself (a <frame>, a fused static parent):
    the compiled pose of the element with its own placement set to the identity."""
    element = spec.body(name) if kind == "body" else spec.site(name)
    if element.frame is None and not spec.compiler.fusestatic:
        return None
    probe = spec.copy()
    moved = probe.body(name) if kind == "body" else probe.site(name)
    moved.pos = [0.0, 0.0, 0.0]
    moved.quat = [1.0, 0.0, 0.0, 0.0]
    moved.alt.type = mujoco.mjtOrientation.mjORIENTATION_QUAT
    m = probe.compile()
    if kind == "body":
        i = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)
        return m.body_quat[i].copy(), m.body_pos[i].copy()
    i = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, name)
    return m.site_quat[i].copy(), m.site_pos[i].copy()


def _body_edit(spec: mujoco.MjSpec, name: str, pos, quat, turned: bool) -> _Edit:
    frame = _frame_of(spec, "body", name)
    if frame is not None:
        q_frame, p_frame = frame
        pos = matrix_from_quat(q_frame).T @ (np.asarray(pos) - p_frame)
        quat = quat_multiply(q_frame * [1.0, -1.0, -1.0, -1.0], quat)
    edit = _Edit({"pos": exact(pos)})
    if turned:
        edit.set["quat"] = exact(canonical_quat(quat))
        edit.remove = tuple(a for a in ALT_ORIENTATIONS if a != "quat")
    return edit


def _site_edit(spec: mujoco.MjSpec, name: str, pos, tag: _Tag) -> _Edit:
    if "fromto" in tag.attrs:
        raise MjcfWriteError(
            f"site '{name}' is placed by 'fromto': give it a 'pos' to write its offset into"
        )
    frame = _frame_of(spec, "site", name)
    if frame is not None:
        q_frame, p_frame = frame
        pos = matrix_from_quat(q_frame).T @ (np.asarray(pos) - p_frame)
    return _Edit({"pos": exact(pos)})


def _find(tags: list[_Tag], tag: str, name: str, where: str) -> _Tag:
    for t in tags:
        if t.tag == tag and t.attrs.get("name") == name:
            return t
    hint = ""
    if any(t.tag == "include" for t in tags):
        hint = " (it is probably in an <include>d file, which this writer does not edit)"
    raise MjcfWriteError(f'{where}: no <{tag} name="{name}"> in the file\'s text{hint}')


def _changed_elements(params: ParameterSet, nominal, injected) -> dict[str, set[int]]:
    """Ids of the bodies, sites and joints whose compiled values the injection changes."""
    kinds: dict[str, set[int]] = {k: set() for k in ("body", "site", "joint")}
    for k, p in enumerate(params.parameters):
        if p.kind not in WRITABLE_KINDS:
            raise MjcfWriteError(
                f"parameter '{p.name}' is of kind '{p.kind}', which is not geometry: it "
                "cannot be written into an MJCF file"
            )
        i = int(params.element[k])
        if p.kind in ("body_pos", "body_rot"):
            same = np.array_equal(nominal.body_pos[i], injected.body_pos[i]) and np.array_equal(
                nominal.body_quat[i], injected.body_quat[i]
            )
            if not same:
                kinds["body"].add(i)
        elif p.kind == "site_pos":
            if not np.array_equal(nominal.site_pos[i], injected.site_pos[i]):
                kinds["site"].add(i)
        elif nominal.qpos0[nominal.jnt_qposadr[i]] != injected.qpos0[nominal.jnt_qposadr[i]]:
            kinds["joint"].add(i)
    return kinds


def _relocated(tags: list[_Tag], source_dir: Path, out_dir: Path) -> list[tuple[_Tag, _Edit]]:
    """Edits that keep relative asset paths pointing at the same files from ``out_dir``."""
    if source_dir.resolve() == out_dir.resolve():
        return []
    dirs = {a for t in tags if t.tag == "compiler" for a in _DIR_ATTRS if a in t.attrs}

    def moved(value: str) -> str:
        if os.path.isabs(value):
            return value
        return os.path.relpath(source_dir.resolve() / value, out_dir.resolve())

    edits = []
    for t in tags:
        change = {}
        if t.tag == "compiler":
            change = {a: moved(t.attrs[a]) for a in _DIR_ATTRS if a in t.attrs}
        elif t.tag == "include" and "file" in t.attrs:
            change = {"file": moved(t.attrs["file"])}
        elif t.tag in _FILE_TAGS and "file" in t.attrs:
            if _FILE_TAGS[t.tag] not in dirs and "assetdir" not in dirs:
                change = {"file": moved(t.attrs["file"])}
        if change:
            edits.append((t, _Edit(change)))
    return edits


def _bounded_masses(tags: list[_Tag]) -> tuple[_Tag, _Edit] | None:
    """MuJoCo's bounded default masses on <compiler> (added after <mujoco> without one), so
    that MuJoCo alone compiles a file whose bodies declare no mass; None if already bounded."""
    bound = {"boundmass": repr(BOUND_MASS), "boundinertia": repr(BOUND_INERTIA)}
    for t in tags:
        if t.tag == "compiler":
            if "boundmass" in t.attrs or "boundinertia" in t.attrs:
                return None
            return t, _Edit(bound)
    attrs = " ".join(f'{k}="{v}"' for k, v in bound.items())
    return tags[0], _Edit(after=f"\n  <compiler {attrs}/>".encode())


@dataclass(frozen=True)
class WrittenMjcf:
    """The patched text and the elements whose values changed in it (by name)."""

    text: str
    bodies: tuple[str, ...]
    sites: tuple[str, ...]
    joints: tuple[str, ...]
    actuators: tuple[str, ...] = ()  # whose gear holds a gain


def _file_units(model: mujoco.MjModel, j: int, spec: mujoco.MjSpec, value):
    """Joint ``j``'s ref or range (SI) in the file's units (degrees for a hinge in a file
    whose compiler says so)."""
    if int(model.jnt_type[j]) == HINGE and spec.compiler.degree:
        return np.degrees(value)
    return value


def _gain_edits(
    tags: list[_Tag],
    nominal: mujoco.MjModel,
    injected: mujoco.MjModel,
    spec: mujoco.MjSpec,
    scales: dict[str, float],
    where: str,
) -> tuple[list[tuple[_Tag, _Edit]], dict[int, float]]:
    """The actuators' gears, the joints' ranges and the keyframes' qpos of gained actuators,
    and the ref (SI) of each gained joint by joint id (see the module's docstring)."""
    edits: list[tuple[_Tag, _Edit]] = []
    refs: dict[int, float] = {}
    factors: dict[int, float] = {}  # qpos address of a gained joint -> qpos per command
    for name, scale in scales.items():
        if not (np.isfinite(scale) and scale > 0):
            raise MjcfWriteError(f"actuator '{name}': 1 + gain = {scale!r} is not positive")
        a = mujoco.mj_name2id(nominal, mujoco.mjtObj.mjOBJ_ACTUATOR, name)
        found = [t for t in tags if t.tag in ACTUATOR_TAGS and t.attrs.get("name") == name]
        if a < 0 or not found:
            raise MjcfWriteError(f"{where}: no actuator named '{name}' in the file's text")
        if float(nominal.actuator_gear[a, 0]) != 1.0:
            raise MjcfWriteError(f"actuator '{name}' already has a gear: it holds no gain")
        j = int(nominal.actuator_trnid[a, 0])
        gear = 1.0 / scale
        edits.append((found[0], _Edit({"gear": exact(gear)})))
        adr = int(nominal.jnt_qposadr[j])
        refs[j] = float(injected.qpos0[adr]) * scale
        factors[adr] = 1.0 / gear  # the qpos of a command: command / gear
        if nominal.jnt_limited[j]:
            joint_name = mujoco.mj_id2name(nominal, mujoco.mjtObj.mjOBJ_JOINT, j)
            rng = _file_units(nominal, j, spec, nominal.jnt_range[j] * factors[adr])
            edits.append((_find(tags, "joint", joint_name, where), _Edit({"range": exact(rng)})))
    for t in tags:
        if t.tag == "key" and "qpos" in t.attrs:
            qpos = np.array(t.attrs["qpos"].split(), dtype=float)
            if len(qpos) != nominal.nq:
                continue  # MuJoCo refuses it; not ours to mend
            for adr, factor in factors.items():
                qpos[adr] *= factor
            edits.append((t, _Edit({"qpos": exact(qpos)})))
    return edits, refs


def mjcf_with_values(
    path: str | os.PathLike[str],
    nominal: mujoco.MjModel,
    params: ParameterSet,
    values: np.ndarray,
    out_dir: str | os.PathLike[str] | None = None,
    header: str | None = None,
    bound_masses: bool = False,
    scales: dict[str, float] | None = None,
) -> WrittenMjcf:
    """The text of the MJCF file ``path`` with ``values`` (SI) of ``params`` written in.

    ``nominal`` is the compiled model of that file that ``params`` is bound to.
    ``out_dir``: where the text will be written; relative asset paths are rewritten to
    point at the same files from there. ``header``: a comment put before <mujoco>.
    ``bound_masses``: add MuJoCo's bounded default masses to <compiler> (for a file whose
    bodies declare no mass, so that MuJoCo alone compiles it). ``scales``: 1 + gain per
    actuator name (the gains as gears, see the module's docstring)."""
    path = Path(path)
    data = path.read_bytes()
    injected = params.inject(nominal, np.asarray(values, dtype=float))
    try:
        spec = mujoco.MjSpec.from_file(str(path))
    except ValueError as exc:
        raise MjcfWriteError(f"MuJoCo could not read {path}: {exc}") from None
    tags = _start_tags(data, str(path))
    edits: list[tuple[_Tag, _Edit]] = []
    changed = _changed_elements(params, nominal, injected)
    refs: dict[int, float] = {}
    if scales:
        gain_edits, refs = _gain_edits(tags, nominal, injected, spec, scales, str(path))
        edits += gain_edits
        changed["joint"] |= set(refs)
    names: dict[str, list[str]] = {"body": [], "site": [], "joint": []}
    obj = {
        "body": mujoco.mjtObj.mjOBJ_BODY,
        "site": mujoco.mjtObj.mjOBJ_SITE,
        "joint": mujoco.mjtObj.mjOBJ_JOINT,
    }
    for kind, ids in changed.items():
        for i in sorted(ids):
            name = mujoco.mj_id2name(nominal, obj[kind], i)
            names[kind].append(name)
            where = _find(tags, kind, name, str(path))
            if kind == "body":
                turned = not np.array_equal(nominal.body_quat[i], injected.body_quat[i])
                edit = _body_edit(spec, name, injected.body_pos[i], injected.body_quat[i], turned)
            elif kind == "site":
                edit = _site_edit(spec, name, injected.site_pos[i], where)
            else:
                ref = refs.get(i, float(injected.qpos0[nominal.jnt_qposadr[i]]))
                edit = _Edit({"ref": exact(float(_file_units(nominal, i, spec, ref)))})
            edits.append((where, edit))
    if out_dir is not None:
        edits += _relocated(tags, path.parent, Path(out_dir))
    if bound_masses:
        bounded = _bounded_masses(tags)
        if bounded is not None:
            edits.append(bounded)
    text = _apply(data, edits).decode("utf-8")
    if header:
        text = with_header(text, header)
    gained = tuple(scales) if scales else ()
    return WrittenMjcf(text, *(tuple(names[k]) for k in ("body", "site", "joint")), gained)


def with_header(text: str, header: str) -> str:
    """``header`` as a comment just before the root element <mujoco>."""
    comment = "<!-- " + header.replace("--", "- -").strip() + " -->\n"
    k = text.find("<mujoco")
    return text[:k] + comment + text[k:] if k >= 0 else comment + text

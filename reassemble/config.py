"""One configuration of a run: every stage's options, nested, and the only place of their defaults.

A :class:`Config` holds the run-level options and one section per stage, each the stage's
own parameter dataclass: ``describe`` (:class:`descriptors.DescriptorParams`), ``segment``
(:class:`segmentation.SegmentParams`), ``features`` (:class:`features.FeatureParams`),
``registration`` (:class:`registration.RegistrationParams`), ``assembly``
(:class:`assembly.AssemblyParams`) and, for ``reassemble break``, ``break``
(:class:`synth.BreakParams`). A run writes it to ``config.json`` with what was decided from
the data filled in (thin walls or not, the contact tolerance, the gap), and
``reassemble run --config config.json`` reads it back: the same options give the same run.
``--set SECTION.NAME=VALUE`` changes one option (:func:`with_setting`).
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from pathlib import Path

from .assembly import AssemblyParams
from .descriptors import DescriptorParams
from .errors import ReassembleError
from .features import FeatureParams
from .files import read_json
from .registration import RegistrationParams
from .retrieval import RetrievalParams
from .segmentation import SegmentParams
from .synth import BreakParams

CONFIG_FORMAT = "reassemble-config/1"
# what config.json records about the data beside the options (read back, not used)
_RECORDED = ("format", "reference_size", "vertex_noise", "note")


@dataclasses.dataclass(frozen=True)
class Config:
    """The options of a run; lengths are fractions of the reference size (the median
    fragment bounding-box diagonal), resolved from the data.

    Parameters
    ----------
    seed : random seed of every stage
    radii : descriptor radii
    gap : how far apart mating fracture surfaces are (material lost at the break); None:
        measured from the pairs (:func:`pairs.match_set`)
    denoise : when the set's vertex noise exceeds this fraction of the finest radius, every
        fragment is matched on a Taubin-smoothed copy (all smoothed alike, until the noisiest
        is down to half that); their own vertices stay in every output
    thin_walls : match as thin-walled sherds along their break strips (:mod:`shells`): None
        when most fragments are (:func:`shells.is_thin_shell`; then as solids too, and the
        assembly with more contact is kept), or always / never
    fill_holes : close the holes of open scans up to this extent, a fraction of each mesh's
        diagonal (:func:`holes.fill_holes`); None reads an open mesh as it is (the winding
        number bridges its holes)
    split_bodies : a file holding several separate bodies gives one fragment per body
        (else a file is one rigid piece, :func:`inputs.load_fragments`)
    describe, segment, features, registration, assembly : the stages' options;
        retrieval : which pairs a large set registers (:mod:`retrieval`)
    break_ : the options of ``reassemble break`` (``break`` in JSON and ``--set``); None in a run
    """

    seed: int = 0
    radii: tuple[float, ...] = (0.02, 0.04, 0.08)
    gap: float | None = None
    denoise: float = 0.2
    thin_walls: bool | None = None
    fill_holes: float | None = None
    split_bodies: bool = False
    describe: DescriptorParams = DescriptorParams(with_d2=False, sphere_area=False, principal=True)
    segment: SegmentParams = SegmentParams()
    features: FeatureParams = FeatureParams()
    registration: RegistrationParams = RegistrationParams()
    retrieval: RetrievalParams = RetrievalParams()
    assembly: AssemblyParams = AssemblyParams()
    break_: BreakParams | None = None

    def check(self) -> None:
        """Raise ReassembleError for options that do not fit together."""
        r = self.retrieval
        for name in ("partners", "more", "max_partners", "neighbours"):
            if getattr(r, name) < 1:
                raise ReassembleError(f"retrieval.{name} must be at least 1, got {getattr(r, name)}")
        if not 0.0 <= r.confidence <= 1.0:
            raise ReassembleError(f"retrieval.confidence must be between 0 and 1, got {r.confidence}")
        n = self.features.signature_radii
        if n is not None and not 1 <= n <= len(self.radii):
            raise ReassembleError(f"features.signature_radii must be 1 to {len(self.radii)} (the descriptor "
                                  f"radii), got {n}")


def _key(f: dataclasses.Field) -> str:
    return f.name.rstrip("_")  # break_ -> break


def _hints(cls) -> dict:
    return typing.get_type_hints(cls)


def _section(tp):
    """The dataclass of a section's type (``BreakParams | None`` -> BreakParams), or None."""
    for t in typing.get_args(tp) or (tp,):
        if dataclasses.is_dataclass(t):
            return t
    return None


def to_dict(obj) -> dict:
    """A config (or section) as plain JSON values, sections nested, ``break_`` as ``break``."""
    return {_key(f): (to_dict(v) if dataclasses.is_dataclass(v) else list(v) if isinstance(v, tuple) else v)
            for f in dataclasses.fields(obj) for v in [getattr(obj, f.name)]}


def _value(tp, value, where: str):
    """``value`` (from JSON or text) as type ``tp``, or a one-line error naming ``where``."""
    args = typing.get_args(tp)
    if isinstance(tp, types.UnionType) or typing.get_origin(tp) is typing.Union:
        if value is None or (isinstance(value, str) and value.strip().lower() in ("none", "auto", "null")):
            if type(None) in args:
                return None
        errors = []
        for t in args:
            if t is type(None):
                continue
            try:
                return _value(t, value, where)
            except ReassembleError as exc:
                errors.append(str(exc))
        raise ReassembleError(errors[0] + (" or none" if type(None) in args else ""))
    if typing.get_origin(tp) is tuple:
        items = value.split(",") if isinstance(value, str) else value
        if not isinstance(items, (list, tuple)) or not items:
            raise ReassembleError(f"{where}: not a list of numbers: {value!r}")
        return tuple(_value(args[0], x, where) for x in items)
    if tp is bool:
        if isinstance(value, str):
            text = value.strip().lower()
            if text in ("true", "yes", "1"):
                return True
            if text in ("false", "no", "0"):
                return False
        if isinstance(value, bool):
            return value
        raise ReassembleError(f"{where}: not true or false: {value!r}")
    if tp is int:
        try:
            number = float(value) if isinstance(value, str) else value
            if isinstance(number, bool) or not isinstance(number, (int, float)) or number != int(number):
                raise ValueError
            return int(number)
        except (ValueError, OverflowError):
            raise ReassembleError(f"{where}: not a whole number: {value!r}") from None
    if tp is float:
        try:
            if isinstance(value, bool):
                raise ValueError
            number = float(value)
        except (TypeError, ValueError):
            raise ReassembleError(f"{where}: not a number: {value!r}") from None
        if not math.isfinite(number):
            raise ReassembleError(f"{where}: not a finite number: {value!r}")
        return number
    if tp is str and isinstance(value, str):
        return value
    raise ReassembleError(f"{where}: cannot read {value!r} as {getattr(tp, '__name__', tp)}")


def from_dict(data: dict, *, source: str = "config", cls=Config, prefix: str = ""):
    """The config in ``data`` (as :func:`to_dict` writes it); options it leaves out keep their
    defaults. Raises ReassembleError naming ``source`` and the option for an unknown option or
    a bad value."""
    if not isinstance(data, dict):
        raise ReassembleError(f"{source}: {prefix.rstrip('.') or 'the configuration'} is not a JSON object")
    fields = {_key(f): f for f in dataclasses.fields(cls)}
    hints = _hints(cls)
    values = {}
    for key, value in data.items():
        if not prefix and key in _RECORDED:
            continue
        if key not in fields:
            raise ReassembleError(f"{source}: unknown option {prefix + key!r} (known: {', '.join(fields)})")
        f = fields[key]
        section = _section(hints[f.name])
        if section is not None and value is not None:
            base = getattr(cls(), f.name) if cls is Config else None
            nested = from_dict(value, source=source, cls=section, prefix=f"{prefix}{key}.")
            values[f.name] = nested if base is None else dataclasses.replace(base, **{
                g.name: getattr(nested, g.name) for g in dataclasses.fields(section) if _key(g) in value})
        else:
            values[f.name] = _value(hints[f.name], value, f"{source}: {prefix}{key}")
    try:
        return cls(**values)
    except TypeError as exc:  # a section without a default for a required option (break.pieces)
        raise ReassembleError(f"{source}: {prefix.rstrip('.')}: {exc}") from None


def read_config(path: str | Path) -> Config:
    """The config of a ``config.json`` (written by a run, or by hand: what it leaves out keeps its default)."""
    config = from_dict(read_json(path, what="a config.json written by 'reassemble run'"), source=str(path))
    config.check()
    return config


def with_setting(config: Config, setting: str) -> Config:
    """``config`` with one option changed: ``setting`` is ``SECTION.NAME=VALUE`` or ``NAME=VALUE``
    (``segment.crease_angle=25``, ``gap=0.01``, ``radii=0.02,0.04``, ``thin_walls=none``)."""
    path, eq, text = setting.partition("=")
    if not eq or not path.strip():
        raise ReassembleError(f"--set {setting!r}: not NAME=VALUE (e.g. segment.crease_angle=25)")
    *sections, name = path.strip().split(".")
    if len(sections) > 1:
        raise ReassembleError(f"--set {setting!r}: options are NAME or SECTION.NAME")
    where = f"--set {path.strip()}"
    if not sections:
        return _replace(config, name, text, where)
    fields = {_key(f): f for f in dataclasses.fields(Config) if _section(_hints(Config)[f.name])}
    if sections[0] not in fields:
        raise ReassembleError(f"--set {setting!r}: unknown section {sections[0]!r} (known: {', '.join(fields)})")
    f = fields[sections[0]]
    current = getattr(config, f.name)
    if current is None:  # break outside 'reassemble break'
        raise ReassembleError(f"--set {setting!r}: section {sections[0]!r} is not used by this command")
    return dataclasses.replace(config, **{f.name: _replace(current, name, text, where)})


def _replace(obj, name: str, text: str, where: str):
    fields = {_key(f): f for f in dataclasses.fields(obj)}
    hints = _hints(type(obj))
    f = fields.get(name)
    if f is None or _section(hints[f.name]) is not None:
        options = [k for k, g in fields.items() if _section(hints[g.name]) is None]
        raise ReassembleError(f"{where}: unknown option {name!r} (known: {', '.join(options)})")
    return dataclasses.replace(obj, **{f.name: _value(hints[f.name], text.strip(), where)})


def with_value(obj, path: str, value):
    """``obj`` (a Config or a section) with the option at ``path`` (``segment.crease_angle``,
    ``break.noise``) set to ``value``, already of the option's type (the CLI's options)."""
    head, _, rest = path.partition(".")
    name = next(f.name for f in dataclasses.fields(obj) if _key(f) == head)
    return dataclasses.replace(obj, **{name: with_value(getattr(obj, name), rest, value) if rest else value})


def default(path: str):
    """The default of one option, by its ``SECTION.NAME`` (``describe.max_memory``)."""
    *sections, name = path.split(".")
    obj = Config()
    if sections:
        f = next(f for f in dataclasses.fields(Config) if _key(f) == sections[0])
        obj = getattr(obj, f.name)
        if obj is None:
            return next(g for g in dataclasses.fields(_section(_hints(Config)[f.name])) if g.name == name).default
    return getattr(obj, name)

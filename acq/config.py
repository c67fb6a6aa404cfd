"""Load bench and profile TOML files into validated models; errors name the file, key and value.

A config error is one line, e.g.::

    configs/benches/lab_canopen.toml: [daq] rate_hz = -25600: must be greater than 0
    configs/benches/lab_canopen.toml: [motor] pole_pair = 4: unknown key (did you mean pole_pairs?)
    configs/profiles/x.toml: top_speed_rpm: missing
    configs/benches/lab.toml: [daq] block_s = 3 must be at most half of buffer_s = 5   (a rule between keys)
"""

from __future__ import annotations

import difflib
import json
import math
import tomllib
from pathlib import Path
from typing import Any, TypeVar, get_args

from pydantic import BaseModel, ValidationError

from drivers.config import Bench, Profile, check_joint_name
from drivers.profile import MAX_DURATION_S
from drivers.registry import CURRENT_SOURCES, DRIVES
from acqcore.errors import ConfigError

CONFIG_DIR = Path(__file__).resolve().parent.parent / "configs"
DEFAULT_BENCH = CONFIG_DIR / "benches" / "sim.toml"
#: sections whose model is chosen by their ``driver`` key → the driver names (the registry's tables)
_DRIVERS_OF = {"daq": set(CURRENT_SOURCES), "drive": set(DRIVES)}

M = TypeVar("M", bound=BaseModel)
#: the sections of a bench file ([motor], [daq], [drive], …): a file with them given as a profile is a bench config
_BENCH_SECTIONS = frozenset(name for name, field in Bench.model_fields.items()
                            if any(isinstance(a, type) and issubclass(a, BaseModel)
                                   for a in (field.annotation, *get_args(field.annotation))))


def _key_path(loc: tuple[Any, ...], data: dict[str, Any]) -> tuple[str, Any]:
    """Turn a pydantic error location into a TOML key path and the value found there."""
    parts: list[str] = []
    node: Any = data
    for i, element in enumerate(loc):
        if i == 1 and element in _DRIVERS_OF.get(loc[0], ()):
            continue  # the discriminated union's tag (e.g. "nidaqmx") is not a key in the file
        if isinstance(element, str) and element.endswith("]"):
            continue
        if isinstance(element, int) and parts:  # an item of a list: channels[1], not a key "1"
            parts[-1] += f"[{element}]"
        else:
            parts.append(str(element))
        node = node.get(element) if isinstance(node, dict) else (
            node[element] if isinstance(node, list) and isinstance(element, int) and element < len(node) else None
        )
    if len(parts) > 1:
        return f"[{'.'.join(parts[:-1])}] {parts[-1]}", node
    return (parts[0] if parts else "(top level)"), node


def _message(error: dict[str, Any]) -> str:
    kind = error["type"]
    if kind == "extra_forbidden":
        return "unknown key"
    if kind == "missing":
        return "missing"
    if kind == "union_tag_invalid":
        return f"unknown driver (expected one of {error.get('ctx', {}).get('expected_tags', '')})"
    if kind == "union_tag_not_found":
        return "missing key 'driver'"
    if kind == "value_error" and "error" in error.get("ctx", {}):  # a validator's own words, without pydantic's prefix
        return str(error["ctx"]["error"])
    ctx = error.get("ctx", {})
    if kind == "too_short":
        return f"must list at least {ctx.get('min_length')}"
    if kind == "too_long":
        return f"must list at most {ctx.get('max_length')}"
    return error["msg"].lower().replace("input should be", "must be")


def _format(path: Path, error: dict[str, Any], data: dict[str, Any]) -> str:
    if error["type"] == "value_error" and "error" in error.get("ctx", {}):
        loc = tuple(error["loc"])
        if not loc or (loc[0] in _DRIVERS_OF and len(loc) <= 2):  # a section's validator: it names its keys
            return f"{path}: {error['ctx']['error']}"
    loc = tuple(error["loc"])
    if error["type"].startswith("union_tag"):
        loc = (*loc, "driver")
    key, value = _key_path(loc, data)
    what = _message(error)
    if error["type"] in ("missing", "union_tag_not_found") or value is None:
        return f"{path}: {key}: missing" if error["type"] == "union_tag_not_found" else f"{path}: {key}: {what}"
    shown = json.dumps(value) if isinstance(value, (str, list, dict, bool)) else repr(value)
    return f"{path}: {key} = {shown}: {what}"


def read_toml(path: Path) -> dict[str, Any]:
    """Parse a TOML file; a missing file or a syntax error becomes a :class:`ConfigError`."""
    try:
        with path.open("rb") as f:
            return tomllib.load(f)
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{path}: not valid TOML: {e}") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not a TOML file (not UTF-8 text)") from None
    except IsADirectoryError:
        raise ConfigError(f"{path}: is a folder, not a TOML file") from None


def validate(model: type[M], data: dict[str, Any], source: Path | str) -> M:
    """Validate ``data`` into ``model``; the first error becomes a one-line :class:`ConfigError`."""
    try:
        return model.model_validate(data)
    except ValidationError as e:
        errors = e.errors()
        # A misspelt key shows up as "unknown" and "missing"; the unknown one names the cause.
        first = next((err for err in errors if err["type"] == "extra_forbidden"), errors[0])
        message = _format(Path(source), first, data)
        section_models = _section_models(model, tuple(first["loc"])) if first["type"] == "missing" else []
        if section_models:  # a whole section
            message = _missing_section(source, tuple(first["loc"]), section_models)
        if first["type"] == "extra_forbidden":
            section = tuple(first["loc"][:-1])
            missing = [str(err["loc"][-1]) for err in errors
                       if err["type"] == "missing" and tuple(err["loc"][:-1]) == section]
            # a missing key first (the typo of a required one); else any key the section accepts that the file does
            # not set (the typo of an optional one, e.g. [sim] host_jiter_s or speed_ditter)
            close = (difflib.get_close_matches(str(first["loc"][-1]), missing, n=1, cutoff=0.6)
                     or difflib.get_close_matches(str(first["loc"][-1]), _unset_keys(model, section, data), n=1,
                                                  cutoff=0.6))
            message += f" (did you mean {close[0]}?)" if close else ""
        raise ConfigError(message) from None


def _section_models(model: type[BaseModel], loc: tuple[Any, ...]) -> list[type[BaseModel]]:
    """The config models of the section at pydantic location ``loc`` of ``model`` (several for a discriminated
    union of drivers); none when ``loc`` names a key, not a section."""
    models: list[type[BaseModel]] = [model]
    for element in loc:
        fields = [m.model_fields[element] for m in models if element in m.model_fields]
        if not fields:
            return []
        models = [m for f in fields for m in _models_in(f.annotation)]
    return models


def _missing_section(source: Path | str, loc: tuple[Any, ...], models: list[type[BaseModel]]) -> str:
    """One line for a section the file lacks, naming what it must hold."""
    section = ".".join(map(str, loc))
    tags = [t for t in map(_tag_of, models) if t is not None]
    if len(models) > 1 and tags:
        return f"{source}: [{section}] missing (driver = one of {', '.join(map(repr, tags))}, and that driver's keys)"
    required = [n for n, f in models[0].model_fields.items() if f.is_required()]
    return f"{source}: [{section}] missing (it needs {', '.join(required)})"


def _unset_keys(model: type[BaseModel], section: tuple[Any, ...], data: dict[str, Any]) -> list[str]:
    """The keys the section at pydantic location ``section`` accepts and ``data`` does not set there.

    A discriminated union's tag in the location (``("drive", "sim")``) picks the member whose ``driver`` is that tag."""
    models: list[type[BaseModel]] = [model]
    node: Any = data
    for element in section:
        fields = [m.model_fields[element] for m in models if element in m.model_fields]
        if fields:
            models = [m for f in fields for m in _models_in(f.annotation)]
            node = node.get(element) if isinstance(node, dict) else None
        else:  # the union's tag: keep the member it names
            models = [m for m in models if _tag_of(m) == element] or models
    present = set(node) if isinstance(node, dict) else set()
    return sorted({key for m in models for key in m.model_fields} - present)


def _models_in(annotation: Any) -> list[type[BaseModel]]:
    """The config models an annotation holds (itself, or the members of an Optional / Union / Annotated)."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    return [m for arg in get_args(annotation) for m in _models_in(arg)]


def _tag_of(model: type[BaseModel]) -> Any:
    """The ``driver`` literal of a discriminated union's member, else None."""
    field = model.model_fields.get("driver")
    args = get_args(field.annotation) if field is not None else ()
    return args[0] if len(args) == 1 else None


def bench_label(path: Path | str | None) -> str:
    """The bench file as messages name it: the path given, or the built-in bench's path relative to the repository."""
    return str(path) if path is not None else str(DEFAULT_BENCH.relative_to(CONFIG_DIR.parent))


def _resolve_shipped(name_or_path: Path | str, folder: str, option: str, what: str) -> Path:
    """A config given as a path, or as a name under ``configs/<folder>/`` (``sim_robot``, ``sim_robot.toml``,
    ``triangle_0.2s``); a relative ``configs/…`` path that is not there (a README example run outside the
    repository) is acq's own ``configs/`` file of that name; a file of the person's own of that name is theirs. A
    name no file answers: :class:`ConfigError` ``<option> <name>: no such file, nor a <what> in <folder>`` listing
    the shipped ones."""
    p = Path(name_or_path)
    if p.exists() or p.is_absolute():
        return p
    if len(p.parts) == 1:  # a name ("triangle_0.2s": its ".2s" is no suffix to replace)
        shipped = CONFIG_DIR / folder / (p.name if p.suffix == ".toml" else f"{p.name}.toml")
    elif p.parts[0] == CONFIG_DIR.name:  # configs/<folder>/x.toml
        shipped = CONFIG_DIR.parent / p
    else:
        return p  # a path of the person's own: read_toml names it
    if shipped.is_file():
        return shipped
    known = sorted(q.stem for q in (CONFIG_DIR / folder).glob("*.toml"))
    raise ConfigError(f"{option} {name_or_path}: no such file, nor a {what} in {CONFIG_DIR / folder} (known: "
                      f"{', '.join(known)})")


def resolve_bench_path(name_or_path: Path | str) -> Path:
    """A bench given as a path or as a shipped bench's name (:func:`_resolve_shipped`, ``configs/benches/``)."""
    return _resolve_shipped(name_or_path, "benches", "--bench", "bench")


def load_bench(path: Path | str | None = None) -> Bench:
    """Load a bench config (a path or a shipped bench's name: :func:`resolve_bench_path`); ``None`` is the built-in
    simulated bench."""
    p = resolve_bench_path(path) if path is not None else DEFAULT_BENCH
    data = read_toml(p)
    if "kind" in data and not _BENCH_SECTIONS & data.keys():
        raise ConfigError(f"{p}: a motion profile (kind = {json.dumps(data['kind'])}), not a bench config: give it as "
                          "--profile")
    drive = data.get("drive")
    if isinstance(drive, dict) and isinstance(drive.get("eds"), str) and drive["eds"] \
            and not Path(drive["eds"]).is_absolute():  # a drive's EDS/DCF named beside the bench file
        drive["eds"] = str(p.parent / drive["eds"])
    return require_analysable(validate(Bench, data, p), p)


def require_analysable(bench: Bench, path: Path) -> Bench:
    """``bench`` if the analysis can use what it records (:mod:`analysis.limits`), else a ConfigError naming the
    file, the key and the value — before anything is recorded (a kHz/Hz mix-up once recorded 78 samples and
    ended in scipy's own words)."""
    from analysis import encoder_period_problem, min_current_rate_hz

    period = bench.drive.period_s
    problem = encoder_period_problem(period)
    if problem is not None:
        raise ConfigError(f"{path}: [drive] period_s = {period:g}: {problem}")
    need = min_current_rate_hz(period)
    if not bench.daq.rate_hz > need:
        raise ConfigError(f"{path}: [daq] rate_hz = {bench.daq.rate_hz:g}: must be above {need:g} Hz for [drive] "
                          f"period_s = {period:g} (the current is filtered up to {need / 2:g} Hz before it is "
                          f"moved onto the encoder's instants)")
    return bench


def resolve_profile_path(name_or_path: str) -> Path:
    """A profile given as a path or as a shipped profile's name (``triangle_0.2s``), by the bench's rules
    (:func:`_resolve_shipped`, ``configs/profiles/``)."""
    return _resolve_shipped(name_or_path, "profiles", "--profile", "profile")


def load_profile(name_or_path: str) -> Profile:
    """Load a motion profile by name or path. A profile file that sets ``dither_seed`` without ``speed_dither`` is an
    error (the seed would choose nothing: the motion repeats exactly); a session file's profile as executed is not
    judged so (a recorded file is what it is)."""
    p = resolve_profile_path(name_or_path)
    data = read_toml(p)
    sections = sorted(_BENCH_SECTIONS & data.keys())
    if "kind" not in data and sections:
        shown = ", ".join(f"[{k}]" for k in sections[:2]) + (" …" if len(sections) > 2 else "")
        raise ConfigError(f"{p}: a bench config (it has {shown}), not a motion profile: give it as --bench")
    profile = validate(Profile, data, p)
    if profile.dither_seed is not None and profile.speed_dither == 0.0:
        raise ConfigError(f"{p}: dither_seed = {profile.dither_seed} without speed_dither: the seed only chooses the "
                          "cycles of a dithered motion (speed_dither = 0, the default, repeats exactly) — set "
                          "speed_dither (e.g. 0.02) or remove dither_seed")
    return profile


def with_joint(bench: Bench, joint: str | None) -> Bench:
    """``bench`` with its joint renamed to ``joint`` (``--joint``); None keeps it. An unsafe name is a ConfigError."""
    if joint is None:
        return bench
    try:
        check_joint_name(joint)
    except ValueError as e:
        raise ConfigError(f"--joint {json.dumps(joint, ensure_ascii=False)}: {e}") from None
    return bench.model_copy(update={"joint": joint})


def check_duration(duration_s: float, source: str = "--duration") -> float:
    """A recording duration in s: finite, > 0 and at most a day; else a ConfigError naming ``source``."""
    if not (0.0 < duration_s <= MAX_DURATION_S):  # also false for NaN
        raise ConfigError(f"{source} {duration_s:g}: must be a number of seconds in (0, {MAX_DURATION_S:g}]")
    return duration_s


#: The streams' start offset a recording of real devices must allow for before it knows it, s: the recorder starts the
#: DAQ task and then the drive's stream (a CANopen SYNC producer / NMT start, a serial stream-on command: round trips
#: of milliseconds), so the first samples of the two lie apart by that start-up. An assumption with a wide margin, not
#: measured on hardware; the simulated bench states its own offset ([sim] daq_offset_s).
STREAM_START_ALLOWANCE_S = 0.1


def min_record_duration_s(bench: Bench, segment_s: float) -> tuple[float, str]:
    """The shortest ``--duration`` (s) after which the identification still has two Welch segments of ``segment_s``
    (:func:`analysis.min_record_s`), and what it is made of (for the message)."""
    from analysis import min_duration_s, min_record_s  # the analysis's libraries only when a duration is checked

    simulated = bench.sim is not None and bench.daq.driver == "sim" and bench.drive.driver == "sim"
    offset_s = abs(bench.sim.daq_offset_s) if simulated and bench.sim is not None else STREAM_START_ALLOWANCE_S
    need_s = min_record_s(bench.daq.rate_hz, bench.drive.period_s, segment_s, offset_s)
    trims_s = need_s - min_duration_s(segment_s) - offset_s
    parts = (f"two {segment_s:g} s Welch segments = {min_duration_s(segment_s):g} s, the streams' start offset "
             f"{offset_s:g} s{' ([sim] daq_offset_s)' if simulated else ''} and {trims_s:.3f} s the analysis trims at "
             "the ends")
    return math.ceil(need_s * 100.0) / 100.0, parts


#: Copies of one block the recording path may hold at once (device read, reader queue, pending flush, writer);
#: measured peak RSS on the simulated bench is ~3 blocks above the baseline, 8 leaves margin.
_BLOCK_COPIES = 8


def check_memory(bench: Bench, available_bytes: int | None = None) -> None:
    """Refuse a bench whose current blocks (and DAQ buffer) would not fit in the memory available.

    Raises :class:`ConfigError` naming the settings and the sizes, before any device is opened or allocated.
    """
    daq = bench.daq
    per_second = daq.rate_hz * len(daq.channels) * 8  # float64 per phase
    need = per_second * (daq.block_s * _BLOCK_COPIES + getattr(daq, "buffer_s", 0.0))
    available = _available_memory() if available_bytes is None else available_bytes
    if available is not None and need > available:
        raise ConfigError(f"[daq] rate_hz = {daq.rate_hz:g} with {len(daq.channels)} channels and block_s = "
                          f"{daq.block_s:g} needs {need / 2**30:.1f} GiB of memory; {available / 2**30:.1f} GiB "
                          "available")


def _available_memory() -> int | None:
    """MemAvailable of /proc/meminfo in bytes (None where there is none)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None

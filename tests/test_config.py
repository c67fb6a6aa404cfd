"""Config validation: every bad input is one line naming file, key and value, exit code 2."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import get_args

import pytest

from acq.config import DEFAULT_BENCH, load_bench, load_profile
from drivers.config import DaqSettings, DriveSettings
from drivers.registry import CURRENT_SOURCES, DRIVES
from tests.helpers import run_cli

SIM_TOML = DEFAULT_BENCH.read_text()


def _bench_with(tmp_path: Path, old: str, new: str) -> Path:
    assert old in SIM_TOML
    p = tmp_path / "bench.toml"
    p.write_text(SIM_TOML.replace(old, new, 1))
    return p


def test_shipped_configs_validate() -> None:
    bench = load_bench()
    assert bench.sim is not None and bench.sim.K_Nm_per_rad == 891.0
    assert bench.daq.rate_hz == 25600 and bench.drive.period_s == 0.001
    for name in ("triangle_0.2s", "triangle_0.5s"):
        profile = load_profile(name)
        assert profile.kind == "triangle" and profile.duration_s == 10


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("rate_hz = 25600", "rate_hz = -25600", "[daq] rate_hz = -25600: must be greater than 0"),
        ("rate_hz = 25600", "rate_hz = \"fast\"", "[daq] rate_hz = \"fast\": must be a valid number"),
        ("pole_pairs = 4", "pole_pair = 4", "[motor] pole_pair = 4: unknown key (did you mean pole_pairs?)"),
        ("pole_pairs = 4", "", "[motor] pole_pairs: missing"),
        # a whole section: before, "motor: missing"; pydantic's "list should have at least 1 item after validation"
        ("[motor]\ntorque_constant_Nm_per_A = 3.0\npole_pairs = 4\n", "",
         "[motor] missing (it needs torque_constant_Nm_per_A, pole_pairs)"),
        ('[daq]\ndriver = "sim"\nrate_hz = 25600\nchannels = ["i_a"]\n', "",
         "[daq] missing (driver = one of 'sim', 'nidaqmx', and that driver's keys)"),
        ('channels = ["i_a"]', "channels = []", "[daq] channels = []: must list at least 1"),
        # a key with a default misspelt: before, "unknown key" alone (only missing keys were offered)
        ("host_jitter_s", "host_jiter_s", "[sim] host_jiter_s = 0.0002: unknown key (did you mean host_jitter_s?)"),
        ("inertia_known", "inertia_knwn", "[nominal] inertia_knwn = true: unknown key (did you mean inertia_known?)"),
        # a tolerance is a fraction of the inertia: 1.5 (a percentage meant?) would accept any k_t
        ("inertia_known = true", "inertia_known = true\ninertia_tolerance = 1.5",
         "[nominal] inertia_tolerance = 1.5: must be less than 1"),
        ("period_s = 0.001", "period_s = 0.001\nmotoin = \"commanded\"",
         "[drive] motoin = \"commanded\": unknown key (did you mean motion?)"),
        # an item of a list by its index: before "[daq.channels] 1 = \"i_x\""
        ('channels = ["i_a"]', 'channels = ["i_a", "i_x"]', "[daq] channels[1] = \"i_x\": must be 'i_a', 'i_b' or "
                                                           "'i_c'"),
        # the sim DAQ has no buffer: nidaqmx's key is not offered for it
        ("rate_hz = 25600", "rate_hz = 25600\nbufer_s = 5", "[daq] bufer_s = 5: unknown key"),
        ("driver = \"sim\"\nrate_hz", "driver = \"labview\"\nrate_hz",
         "[daq] driver = \"labview\": unknown driver (expected one of 'sim', 'nidaqmx')"),
        ("counts_per_rev = 131072", "counts_per_rev = 131072.5",
         "[encoder] counts_per_rev = 131072.5: must be a valid integer"),
        # a phase twice: HDF5 failed at the start ("Unable to synchronously create dataset (name already exists)")
        ('channels = ["i_a"]', 'channels = ["i_a", "i_a"]',
         '[daq] channels = ["i_a", "i_a"]: i_a is listed twice (each phase is one channel)'),
        ('channels = ["i_a"]', 'channels = ["i_a", "i_b", "i_b"]',
         '[daq] channels = ["i_a", "i_b", "i_b"]: i_b is listed twice (each phase is one channel)'),
        # a validator's words without pydantic's "value error, " before them
        ('joint = "joint1"', 'joint = "a b"', "joint = \"a b\": may hold only letters, digits, '-', '_' and '.' "
                                              "(not ' ')"),
        # rules between the bench and the analysis: refused before a sample is recorded
        ("rate_hz = 25600", "rate_hz = 25.6",  # a kHz/Hz mix-up
         "[daq] rate_hz = 25.6: must be above 1200 Hz for [drive] period_s = 0.001 (the current is filtered up to "
         "600 Hz before it is moved onto the encoder's instants)"),
        ("period_s = 0.001", "period_s = 1",
         "[drive] period_s = 1: the encoder then samples at 1 Hz, too slow for the fit band (from 10 Hz to 0.4 × "
         "its rate = 0.4 Hz): it must be below 0.04 s"),
    ],
)
def test_bad_bench_config_is_one_line_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                             old: str, new: str, message: str) -> None:
    path = _bench_with(tmp_path, old, new)
    run = run_cli(capsys, "record", "--profile", "triangle_0.2s", "--bench", str(path), "--fast",
                  "--out", str(tmp_path / "s"))
    assert run.code == 2
    assert run.err.strip() == f"acq: error: {path}: {message}"
    assert "Traceback" not in run.err
    assert not (tmp_path / "s").exists(), "no session file for a rejected config"


def test_toml_syntax_error_names_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "broken.toml"
    path.write_text("joint = \n")
    run = run_cli(capsys, "record", "--profile", "triangle_0.2s", "--bench", str(path))
    assert run.code == 2
    assert run.err.startswith(f"acq: error: {path}: not valid TOML:")
    assert len(run.err.strip().splitlines()) == 1


def test_unknown_profile_lists_known_ones(capsys: pytest.CaptureFixture[str]) -> None:
    run = run_cli(capsys, "record", "--profile", "sawtooth")
    assert run.code == 2
    from acq.config import CONFIG_DIR

    assert run.err.strip() == (f"acq: error: --profile sawtooth: no such file, nor a profile in "
                               f"{CONFIG_DIR / 'profiles'} (known: triangle_0.2s, triangle_0.5s)")


def test_bad_profile_value(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "p.toml"
    text = (Path(__file__).parent.parent / "configs/profiles/triangle_0.2s.toml").read_text()
    path.write_text(text.replace("accel_time_s = 0.2", "accel_time_s = 0"))
    assert tomllib.loads(path.read_text())["accel_time_s"] == 0
    run = run_cli(capsys, "record", "--profile", str(path))
    assert run.code == 2
    assert run.err.strip() == f"acq: error: {path}: accel_time_s = 0: must be greater than 0"


def test_a_misspelt_optional_profile_key_is_named_with_the_key_meant(tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "p.toml"
    text = (Path(__file__).parent.parent / "configs/profiles/triangle_0.2s.toml").read_text()
    path.write_text(text.replace("speed_dither = 0.02", "speed_ditter = 0.0"))
    run = run_cli(capsys, "record", "--profile", str(path))
    assert run.code == 2
    assert run.err.strip() == f"acq: error: {path}: speed_ditter = 0.0: unknown key (did you mean speed_dither?)"


def test_a_bench_given_as_profile_and_a_profile_given_as_bench_are_named_so(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Before: 'sim.toml: joint = "joint1": unknown key' and 'triangle_0.2s.toml: kind = "triangle": unknown key'."""
    profile = Path(__file__).parent.parent / "configs/profiles/triangle_0.2s.toml"
    as_profile = run_cli(capsys, "record", "--profile", str(DEFAULT_BENCH), "--fast")
    assert (as_profile.code, as_profile.err.strip()) == (
        2, f"acq: error: {DEFAULT_BENCH}: a bench config (it has [daq], [drive] …), not a motion profile: give it as "
           "--bench")
    as_bench = run_cli(capsys, "record", "--profile", "triangle_0.2s", "--bench", str(profile), "--fast")
    assert (as_bench.code, as_bench.err.strip()) == (
        2, f'acq: error: {profile}: a motion profile (kind = "triangle"), not a bench config: give it as --profile')
    typo = tmp_path / "p.toml"  # a profile whose kind is misspelt is still judged as a profile
    typo.write_text(profile.read_text().replace('kind = "triangle"', 'knd = "triangle"'))
    assert run_cli(capsys, "record", "--profile", str(typo), "--fast").err.strip() == (
        f'acq: error: {typo}: knd = "triangle": unknown key (did you mean kind?)')


def test_missing_bench_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = run_cli(capsys, "record", "--profile", "triangle_0.2s", "--bench", str(tmp_path / "nope.toml"))
    assert run.code == 2
    assert run.err.strip() == f"acq: error: {tmp_path / 'nope.toml'}: no such file"


def test_a_bench_is_found_by_its_name_as_a_profile_is(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """The trial: --bench sim_robot said "sim_robot: no such file", and README's --bench
    configs/benches/sim_robot.toml failed outside the repository."""
    from acq.config import CONFIG_DIR, resolve_bench_path

    monkeypatch.chdir(tmp_path)  # outside the repository
    shipped = CONFIG_DIR / "benches" / "sim_robot.toml"
    assert [resolve_bench_path(n) for n in ("sim_robot", "sim_robot.toml", "configs/benches/sim_robot.toml")] == \
        [shipped] * 3
    (tmp_path / "sim_robot.toml").write_text("x = 1\n")  # a file of the person's own is theirs
    assert resolve_bench_path("sim_robot.toml") == Path("sim_robot.toml")
    known = ", ".join(sorted(q.stem for q in (CONFIG_DIR / "benches").glob("*.toml")))
    run = run_cli(capsys, "monitor", "--bench", "sim_robt", "--for", "1s", "--window", "1", "--every", "1", "--fast")
    assert (run.code, run.err) == (2, f"acq: error: --bench sim_robt: no such file, nor a bench in "
                                      f"{CONFIG_DIR / 'benches'} (known: {known})\n")
    run = run_cli(capsys, "selftest", "--bench", "sim", "--fast", "--json")
    assert run.code == 0, run.err


def test_a_profile_resolves_as_a_bench_does_outside_the_repository(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """The new user's trial: from outside the repository README's --profile configs/profiles/triangle_0.2s.toml and
    --profile triangle_0.2s.toml said "no such file" while --bench configs/benches/sim.toml and --bench sim.toml
    worked."""
    from acq.config import CONFIG_DIR, resolve_profile_path

    monkeypatch.chdir(tmp_path)  # outside the repository
    shipped = CONFIG_DIR / "profiles" / "triangle_0.2s.toml"
    assert [resolve_profile_path(n) for n in ("triangle_0.2s", "triangle_0.2s.toml",
                                              "configs/profiles/triangle_0.2s.toml")] == [shipped] * 3
    (tmp_path / "triangle_0.2s.toml").write_text("x = 1\n")  # a file of the person's own is theirs
    assert resolve_profile_path("triangle_0.2s.toml") == Path("triangle_0.2s.toml")
    run = run_cli(capsys, "record", "--profile", "configs/profiles/triangle_0.2s.toml", "--fast", "--duration", "1",
                  "--no-analyze", "--out", str(tmp_path / "s"))
    assert run.code == 0, run.err
    run = run_cli(capsys, "record", "--profile", "configs/profiles/sawtooth.toml", "--fast")
    assert (run.code, run.err) == (2, f"acq: error: --profile configs/profiles/sawtooth.toml: no such file, nor a "
                                      f"profile in {CONFIG_DIR / 'profiles'} (known: triangle_0.2s, triangle_0.5s)\n")


def test_a_binary_file_given_as_bench_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "session.h5"
    path.write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(range(256)))
    run = run_cli(capsys, "record", "--profile", "triangle_0.2s", "--bench", str(path))
    assert run.code == 2
    assert run.err.strip() == f"acq: error: {path}: not a TOML file (not UTF-8 text)"


def test_folders_where_files_are_expected_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "x.h5"
    folder.mkdir()
    run = run_cli(capsys, "info", str(folder))
    assert run.code == 2 and run.err.strip() == f"acq: error: {folder}: is a folder, not a session file"
    out_file = tmp_path / "taken"
    out_file.write_text("")
    run = run_cli(capsys, "record", "--profile", "triangle_0.2s", "--fast", "--duration", "1", "--out", str(out_file))
    assert run.code == 2
    assert run.err.strip() == f"acq: error: --out {out_file}: is a file, not a folder"


def test_every_driver_the_config_accepts_has_an_adapter_in_the_registry() -> None:
    def tags(union: object) -> set[str]:
        models = get_args(get_args(union)[0])
        return {get_args(m.model_fields["driver"].annotation)[0] for m in models}

    assert (tags(DaqSettings), tags(DriveSettings)) == (set(CURRENT_SOURCES), set(DRIVES))

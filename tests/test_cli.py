"""Every bad input of the CLI exits 2 with one clean line; warnings print as one line."""

import warnings

import pytest

from sidql.commands import main as cli
from sidql.commands.usage import one_line_warning
from sim.errors import MotionDataWarning


def one_error_line(capsys, command: str) -> str:
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith(f"sidql {command}: error: "), err
    assert "Traceback" not in err and "KeyError" not in err and "SystemExit" not in err
    return lines[0]


@pytest.fixture
def trial(cmu_dir):
    return str(cmu_dir / "02" / "02.asf"), str(cmu_dir / "02" / "02_01.amc")


def test_bad_w_exits_2_with_one_line(trial, tmp_path, capsys):
    asf, amc = trial
    for argv, command in (
        (["extract", asf, amc, "--keyframes", "1"], "extract"),
        (["eval", "--data", str(tmp_path), "--keyframes", "99", "--out", "x"], "eval"),
        (["report", asf, amc, "-W", "0", "--out", str(tmp_path / "r")], "report"),
        (["train", "--data", str(tmp_path), "--keyframes", "2"], "train"),
    ):
        assert cli.main(argv) == 2, argv
        assert "--keyframes" in one_error_line(capsys, command)


def test_unknown_method_exits_2_with_one_unquoted_line(trial, tmp_path, capsys):
    asf, amc = trial
    assert cli.main(["extract", asf, amc, "--keyframes", "6", "--methods", "nope"]) == 2
    line = one_error_line(capsys, "extract")
    assert "unknown method 'nope'; known:" in line and not line.endswith('"')
    assert cli.main(["report", asf, amc, "--methods", "nope", "--out", str(tmp_path)]) == 2
    assert "known:" in one_error_line(capsys, "report")


def test_unparsable_argument_exits_2_with_one_line(capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["extract", "a.asf", "b.amc", "--keyframes", "six"])
    assert e.value.code == 2
    assert "invalid int value: 'six'" in one_error_line(capsys, "extract")


def test_missing_file_exits_2_naming_it(tmp_path, capsys):
    missing = tmp_path / "none.asf"
    assert cli.main(["ingest", str(missing), str(tmp_path / "x.amc"), "--out", "o.npz"]) == 2
    assert "none.asf" in one_error_line(capsys, "ingest")


def test_warnings_print_as_one_line_naming_the_data_file(capsys):
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.showwarning = one_line_warning
        warnings.warn(MotionDataWarning("/d/07_12.amc:7324: truncated frame 245"), stacklevel=1)
        warnings.warn("plain", UserWarning, stacklevel=1)
    err = capsys.readouterr().err.splitlines()
    assert err[0] == "warning: /d/07_12.amc:7324: truncated frame 245"
    assert err[1].startswith("warning: ") and "test_cli.py:" in err[1]
    assert err[1].endswith(": plain")
    assert len(err) == 2


def test_the_dropped_final_frame_warns_in_one_line_through_the_cli(cmu_dir, tmp_path, capsys):
    amc = tmp_path / "02_cut.amc"
    lines = (cmu_dir / "02" / "02_01.amc").read_text().splitlines()
    frame_starts = [i for i, ln in enumerate(lines) if ln.strip().isdigit()]
    amc.write_text("\n".join(lines[: frame_starts[12] + 5]) + "\n")  # frame 12 incomplete
    rc = cli.main(
        ["ingest", str(cmu_dir / "02" / "02.asf"), str(amc), "--out", str(tmp_path / "o.npz")]
    )
    assert rc == 0
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1 and err[0].startswith(f"warning: {amc}:"), err


def test_a_folder_without_clips_exits_2_with_one_line(tmp_path, capsys):
    assert (
        cli.main(["eval", "--data", str(tmp_path), "--out", str(tmp_path / "r.json"), "--quiet"])
        == 2
    )
    assert "no 60-frame clips" in one_error_line(capsys, "eval")


def test_bad_counts_rates_and_out_paths_exit_2_and_leave_nothing(trial, tmp_path, capsys):
    """--workers -1 (a ProcessPoolExecutor ValueError), synth --fps 0 (ZeroDivisionError),
    synth --seconds 0 (every task an IndexError), an output path that is a folder (OSError) were
    tracebacks or exit 1; input checks ran after the output folder was made."""
    asf, amc = trial
    out = tmp_path / "out"
    for argv, command in (
        (["dataset", "--data", str(tmp_path), "--out", str(out), "--workers", "-1"], "dataset"),
        (["eval", "--data", str(tmp_path), "--workers", "0", "--out", str(out)], "eval"),
        (["synth", "--n", "1", "--out", str(out), "--fps", "0"], "synth"),
        (
            ["synth", "--n", "1", "--out", str(out), "--seconds", "0", "--kinds", "procedural"],
            "synth",
        ),
        (
            ["synth", "--n", "1", "--out", str(out), "--seconds", "0.01", "--kinds", "procedural"],
            "synth",
        ),
        (["synth", "--n", "1", "--out", str(out), "--data", str(tmp_path / "no")], "synth"),
        (["dataset", "--data", str(tmp_path / "no"), "--out", str(out)], "dataset"),
        (["encode", asf, amc, "--out", str(tmp_path), "--max-q", "0.05"], "encode"),
    ):
        try:
            code = cli.main(argv)
        except SystemExit as e:  # argparse's own errors
            code = e.code
        assert code == 2, argv
        one_error_line(capsys, command)
        assert not out.exists(), argv
    assert (
        cli.main(["encode", asf, amc, "--out", str(out / "a" / "w.sidq"), "--max-q", "0.05"]) == 0
    )
    amc_out = out / "b" / "w.amc"
    assert cli.main(["decode", str(out / "a" / "w.sidq"), "--out", str(amc_out), "--asf", asf]) == 0
    assert amc_out.is_file()


def test_a_rate_that_does_not_divide_120_exits_2_with_one_line(trial, tmp_path, capsys):
    """ingest/extract --fps 7 were ValueError tracebacks; dataset/eval listed every trial as bad."""
    asf, amc = trial
    for argv in (
        ["ingest", asf, amc, "--out", str(tmp_path / "x.npz"), "--fps", "7"],
        ["extract", asf, amc, "--keyframes", "5", "--fps", "7"],
        ["dataset", "--data", str(tmp_path), "--out", str(tmp_path / "o"), "--fps", "7"],
        ["eval", "--data", str(tmp_path), "--out", str(tmp_path / "r.json"), "--fps", "7"],
    ):
        with pytest.raises(SystemExit) as e:
            cli.main(argv)
        assert e.value.code == 2
        assert "must divide 120" in one_error_line(capsys, argv[0])
    assert cli.main(["ingest", asf, amc, "--out", str(tmp_path / "y.npz"), "--fps", "40"]) == 0


def test_report_on_a_skeleton_without_the_protocol_bones_exits_2(cmu_dir, tmp_path, capsys):
    """A well-formed trial naming a bone otherwise was a KeyError traceback (restrict(POINTS))."""
    for name in ("02.asf", "02_01.amc"):
        text = (cmu_dir / "02" / name).read_text().replace("lhumerus", "lupperarm")
        (tmp_path / name).write_text(text)
    out = tmp_path / "rep"
    argv = ["report", str(tmp_path / "02.asf"), str(tmp_path / "02_01.amc"), "--no-video"]
    assert cli.main([*argv, "--methods", "uniform", "--out", str(out)]) == 2
    line = one_error_line(capsys, "report")
    assert "02_01.amc" in line and "lacks protocol point(s) lhumerus" in line
    assert not out.exists()


def test_a_source_rate_the_output_rate_does_not_divide_exits_2_with_one_line(
    trial, tmp_path, capsys
):
    """ingest --source-fps 7 was a 19-line ValueError traceback with exit 1; the library raises
    a UsageError where the rates meet (sim.motion.ingest.resample_step)."""
    asf, amc = trial
    out = tmp_path / "x.npz"
    assert cli.main(["ingest", asf, amc, "--out", str(out), "--source-fps", "7"]) == 2
    line = one_error_line(capsys, "ingest")
    assert "output rate 30.0 fps must divide the source rate 7.0 fps" in line
    with pytest.raises(SystemExit) as e:
        cli.main(["ingest", asf, amc, "--out", str(out), "--source-fps", "0"])
    assert e.value.code == 2 and "must be positive" in one_error_line(capsys, "ingest")
    assert not out.exists()


def test_a_resample_step_refuses_bad_rates_with_a_usage_error():
    from sim.errors import UsageError
    from sim.motion.ingest import resample_step

    assert resample_step(120.0, 30.0) == 4
    for source, fps in ((7.0, 30.0), (0.0, 30.0), (120.0, -1.0), (float("inf"), 30.0),
                        (float("nan"), 30.0)):  # fmt: skip
        with pytest.raises(UsageError):
            resample_step(source, fps)


def test_report_clip_numbers_out_of_range_exit_2_naming_them(trial, tmp_path, capsys):
    """The catch-all ``except ValueError`` of the report command is gone: the library raises a
    UsageError for clip numbers the trial does not have."""
    asf, amc = trial
    out = tmp_path / "rep"
    argv = ["report", asf, amc, "--methods", "uniform", "--clips", "999", "--no-video"]
    assert cli.main([*argv, "--out", str(out), "--quiet"]) == 2
    assert "clip numbers [999] out of range" in one_error_line(capsys, "report")
    assert not out.exists()

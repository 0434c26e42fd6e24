"""hri_physio_evaluate's command line: a small run's files, and bad input -> one line, status 2."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from hri_physio_coach.evaluate.cli import main
from hri_physio_coach.evaluate.summary import SUMMARY_COLUMNS

SMALL = ["--cohort", "2", "--seed", "3", "--policies", "threshold,predictive", "--jobs", "1",
         "--traces", "1", "--bootstrap", "100", "--progress", "false"]


def error_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("hri_physio_evaluate: error: ")
    return err[0]


def test_a_small_run_writes_every_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "eval"
    assert main([*SMALL, "--out", str(out)]) == 0
    assert "predictive" in capsys.readouterr().out
    for name in ("sessions.csv", "summary.csv", "summary.md", "in_zone.png", "traces.png"):
        assert (out / name).stat().st_size > 0, name
    sessions = pd.read_csv(out / "sessions.csv")
    assert len(sessions) == 4 and set(sessions["policy"]) == {"threshold", "predictive"}
    for column in ("in_zone", "in_zone_warm_up", "in_zone_cool_down", "time_to_zone_s", "above_hrr70_s",
                   "rms_to_centre_bpm", "adaptations_conditioning", "reversals", "cooldown_end_frac_hrr",
                   "reachable", "reach"):
        assert column in sessions.columns
    assert sessions["in_zone"].between(0, 1).all()
    summary = pd.read_csv(out / "summary.csv")
    assert list(summary.columns) == list(SUMMARY_COLUMNS)
    assert list(summary["policy"]) == ["threshold", "predictive"]
    md = (out / "summary.md").read_text()
    assert "| predictive | threshold |" in md and "hri_physio_evaluate --cohort 2" in md
    # The same seed gives the same sessions.
    again = tmp_path / "again"
    assert main([*SMALL, "--out", str(again)]) == 0
    pd.testing.assert_frame_equal(sessions, pd.read_csv(again / "sessions.csv"))


def test_a_population_file_replaces_the_sampled_cohort(tmp_path: Path) -> None:
    population = tmp_path / "people.csv"
    population.write_text("age,hr_rest,hr_max_true,vo2max,female\n30,60,190,45,false\n45,75,175,30,true\n")
    out = tmp_path / "eval"
    assert main([*SMALL, "--population", str(population), "--out", str(out)]) == 0
    sessions = pd.read_csv(out / "sessions.csv")
    assert sorted(set(sessions["age"])) == [30.0, 45.0]


@pytest.mark.parametrize(("args", "names"), [
    (["--policies", "threshold,bogus"], "bogus"),
    (["--policies", "threshold,threshold"], "policies"),
    (["--cohort", "0"], "cohort"),
    (["--cohort", "-5"], "cohort"),
    (["--seed", "-1"], "seed: expected greater than or equal to 0"),
    (["--age-min", "60", "--age-max", "50"], "age_min"),
    (["--hr-latency", "abc"], "hr_latency"),
    (["--coach-conf", "/nonexistent/coach.yaml"], "coach.yaml"),
])
def test_bad_options(args: list[str], names: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([*args, "--out", str(tmp_path / "x")]) == 2
    assert names in error_line(capsys)
    assert not (tmp_path / "x" / "sessions.csv").exists()


def test_a_coach_option_that_does_not_fit_a_person_of_the_cohort(tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """The coach's options are checked with each person's age before any session runs."""
    conf = tmp_path / "coach.yaml"
    conf.write_text("calib_skip: true\nresting_default: 150\n")
    args = ["--cohort", "2", "--age-min", "85", "--age-max", "95", "--coach-conf", str(conf)]
    assert main([*args, "--out", str(tmp_path / "x")]) == 2
    assert "resting_default 150 bpm must be below the participant's HR_max" in error_line(capsys)
    assert not (tmp_path / "x" / "sessions.csv").exists()


def test_unwritable_out_dir(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    blocker = tmp_path / "a_file"
    blocker.write_text("not a directory")
    assert main(["--cohort", "1", "--out", str(blocker / "sub")]) == 2
    assert "out: cannot write" in error_line(capsys)


@pytest.mark.parametrize(("content", "names"), [
    (None, "does not exist"),
    ("", "no rows"),
    ("age,hr_rest\n", "no rows"),
    ("age,shoe_size\n30,42\n", "shoe_size"),
    ("age;hr_rest\n30;60\n", "split by semicolons: columns are separated by commas"),
    ("age\thr_rest\n30\t60\n", "split by tabs"),
    ("age,hr_rest\n30,fast\n", "hr_rest must be a number"),
    ("age,hr_rest\n30,\n", "needs a value"),
    ("age,hr_rest,hr_max_true\n30,200,180\n", "hr_rest < hr_max_true"),
    ("age\n30\n", "fewer than the cohort"),
    ("age,tau_on\n30,nan\n30,60\n", "line 2: invalid participant: tau_on must be a finite number, got nan"),
    ("age,dead_time\n30,8\n30,inf\n", "line 3: invalid participant: dead_time must be a finite number"),
    ("age,marching_mets\n30,-5\n30,3\n", "marching_mets must be >= 1"),
    ("age,artefact_rate\n30,7\n30,0\n", "artefact_rate must be in [0, 1]"),
    ("age,step_height\n30,0\n30,0.1\n", "step_height must be > 0 m"),
])
def test_bad_population_file(content: str | None, names: str, tmp_path: Path,
                             capsys: pytest.CaptureFixture[str]) -> None:
    population = tmp_path / "people.csv"
    if content is not None:
        population.write_text(content)
    assert main(["--cohort", "2", "--population", str(population), "--out", str(tmp_path / "x")]) == 2
    line = error_line(capsys)
    assert names in line and "people.csv" in line


def test_unknown_flag_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--cohrt", "3"])
    assert exc.value.code == 2
    assert "--cohrt" in capsys.readouterr().err


def test_the_sensitivity_sweep_moves_each_assumption_to_both_ends(tmp_path: Path) -> None:
    out = tmp_path / "eval"
    args = [*SMALL, "--sensitivity", "--sensitivity-cohort", "1", "--sensitivity-policies", "threshold"]
    assert main([*args, "--out", str(out)]) == 0
    table = pd.read_csv(out / "sensitivity.csv")
    variants = list(table["variant"])
    assert variants[0] == "main" and len(variants) == 1 + 2 * 9
    assert {"tempo_compliance=0.3", "tempo_compliance=1", "gesture_gain=0", "gesture_gain=0.5", "tau_on=20",
            "tau_on=120", "tau_off=25", "tau_off=140"} <= set(variants)
    assert {"winner", "winner_still_best", "predictive_median", "threshold_mean", "p_vs_threshold"} <= set(
        table.columns)
    assert set(table["winner"]) == {"predictive"}  # the winner is always swept, with the policies asked for
    swept = pd.read_csv(out / "sensitivity_sessions.csv")
    assert len(swept) == 18 * 2 and set(swept.loc[swept.variant == "gesture_gain=0.5", "participant"]) == {0}
    assert "## Sensitivity" in (out / "summary.md").read_text()


def test_ctrl_c_is_one_line_and_status_130(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    from hri_physio_coach.evaluate import cli

    def interrupted(*_args: object, **_kwargs: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "run_evaluation", interrupted)
    assert main(["--cohort", "1", "--out", str(tmp_path / "x")]) == 130
    assert "interrupted before the evaluation finished" in capsys.readouterr().err


def test_an_evaluation_ended_early_drops_the_chunks_not_started(monkeypatch: pytest.MonkeyPatch) -> None:
    """Ctrl-C (or an error) while local workers run: the pool is shut down with its queued chunks
    cancelled, not after running every one of them."""
    from hri_physio_coach.evaluate import runner

    shutdowns: list[dict[str, bool]] = []

    class Pool(runner.ProcessPoolExecutor):  # type: ignore[misc]
        def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
            shutdowns.append({"wait": wait, "cancel_futures": cancel_futures})
            super().shutdown(wait=wait, cancel_futures=cancel_futures)

    monkeypatch.setattr(runner, "ProcessPoolExecutor", Pool)
    chunks = [[] for _ in range(20)]  # empty chunks: each worker call returns at once
    done = runner._local(chunks, None, 2)
    next(done)
    done.close()  # what a KeyboardInterrupt in the loop over results does to the generator
    assert shutdowns and shutdowns[0]["cancel_futures"]

"""`neuralao report`'s flags and settings refused before any work (one line, exit 2, no --out left
behind), and the one line that Ctrl-C and SIGTERM end a command with: no empty line before it, no
progress bar drawn again after it. The commands run for real, in-process (a process where a signal is
sent to it), on a tiny dataset built here."""

from __future__ import annotations

import gc
import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest
from test_user_inputs import NEURALAO, refusal

from neuralao.pipeline.cli.main import Terminated, main
from neuralao.pipeline.datasets.dataset import DatasetSettings, SceneSpec, build_dataset
from neuralao.pipeline.tracing.labeller import LabelSettings


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> Path:
    """A dataset of one val scene, two 16x16 views: every view is an evaluation frame."""
    root = tmp_path_factory.mktemp("report_inputs") / "dataset"
    settings = DatasetSettings(
        name="tiny",
        scenes=[SceneSpec("box", "cornell_box", cameras="interior", views=2, split="val")],
        size=(16, 16),
        labels=LabelSettings(rays=8),
        frames_per_shard=2,
    )
    build_dataset(settings, root, progress=False)
    return root


def _report(data: Path, out: Path, *extra: str) -> list[str]:
    """A report that would take seconds, then ``extra`` (a later flag wins over an earlier one)."""
    base = ["--gt-rays", "8", "--frames-per-scene", "1", "--time-size", "16", "16", "--repeats", "1"]
    return ["report", "--data", str(data), *base, "--out", str(out), *extra]


@pytest.mark.parametrize(
    "extra,words",
    [
        (["--no-shipped", "--set", "ssao.samples=0"], "ssao.samples must be an integer in [1, 128], got 0"),
        (["--no-shipped", "--set", "gtao.slices=1000"], "gtao.slices must be an integer in [1, 64]"),
        (["--no-shipped", "--set", "ssao.bias_rel=2"], "ssao.bias_rel must be a fraction"),
        (["--no-shipped", "--gt-rays", "1000000000000"], "--gt-rays 1000000000000 is more than this machine"),
        (["--no-shipped", "--set", "trace_rays=[4,1000000000000]"], "trace_rays 1000000000000 is more"),
        (["--no-shipped", "--time-size", "100000", "100000"], "--time-size must be between 1 and 8192"),
        (["--no-shipped", "--repeats", "0"], "--repeats must be >= 1"),
        (["--no-shipped", "--set", "workers=0"], "workers must be >= 1"),
        (["--no-shipped", "--exports", "@missing"], "--exports @missing: no such folder"),
        (["--no-shipped", "--exports", "@file"], "--exports @file is a file, not a folder"),
        (["--models", "@missing"], "--models @missing: no such folder"),
        (["--no-shipped", "--models", "@empty"], "--no-shipped leaves them out"),
        (["--exports", "@empty", "--models", "@empty"], "unless --shipped asks for them"),
    ],
)
def test_bad_flags_and_settings_are_refused_before_any_work(tmp_path, capsys, data, extra, words):
    (tmp_path / "empty").mkdir()
    (tmp_path / "file").write_text("x")
    paths = {"@missing": tmp_path / "missing", "@empty": tmp_path / "empty", "@file": tmp_path / "file"}
    extra = [str(paths.get(a, a)) for a in extra]
    for token, path in paths.items():
        words = words.replace(token, str(path))
    out = tmp_path / "out"
    msg = refusal(capsys, _report(data, out, *extra))
    assert msg.startswith("neuralao report: error: ") and words in msg, msg
    assert not out.exists()  # nothing made: no folder, no caches


def test_a_setting_from_the_config_file_is_refused_naming_the_file(tmp_path, capsys, data):
    config = tmp_path / "preset.json"
    config.write_text(json.dumps({"ssao": {"samples": 500}}))
    out = tmp_path / "out"
    msg = refusal(capsys, _report(data, out, "--no-shipped", "--config", str(config)))
    assert f"ssao.samples (config file {config}) must be an integer in [1, 128], got 500" in msg, msg
    assert not out.exists()


def test_a_missing_dataset_leaves_no_output_folder(tmp_path, capsys):
    out = tmp_path / "out"
    msg = refusal(capsys, ["report", "--data", str(tmp_path / "none"), "--no-shipped", "--out", str(out)])
    assert "no dataset manifest" in msg and not out.exists()


# --------------------------------------------------------------------------- Ctrl-C and SIGTERM


@pytest.mark.parametrize(
    "signal_error,code,line",
    [
        (KeyboardInterrupt, 130, "neuralao report: interrupted (Ctrl-C)"),
        (Terminated, 143, "neuralao report: terminated (SIGTERM)"),
    ],
)
def test_a_signal_during_a_progress_bar_ends_its_line_once(
    tmp_path, capsys, monkeypatch, data, signal_error, code, line
):
    """The signal comes while the report's bar is drawn and open: the bar's line is ended, the message is
    the next line (none empty between) and the last one (the bar is not drawn again when collected)."""
    from neuralao.pipeline.evaluation import report

    def interrupted(*args, **kwargs):
        raise signal_error()

    monkeypatch.setattr(report, "SceneContext", interrupted)  # inside the loop over scenes, bar shown
    assert main(_report(data, tmp_path / "out", "--no-shipped")) == code
    gc.collect()  # a bar left open would be closed, and drawn, now
    err = [ln for ln in capsys.readouterr().err.split("\n") if not ln.startswith(("INFO ", "WARNING "))]
    assert err[-2:] == [line, ""], err  # the message, then nothing
    assert "report:" in err[-3] and "[00:" in err[-3], err  # right after the bar's ended line


def test_ctrl_c_of_a_run_without_a_terminal_is_exactly_one_line(tmp_path):
    """No progress bar on stderr (--no-progress, not a terminal): stderr is the message alone."""
    config = {
        "name": "slow",
        "size": [64, 64],
        "frames_per_shard": 1,
        "labels": {"rays": 4096},
        "scenes": [
            {"name": "box", "mesh": "cornell_box", "cameras": "interior", "views": 32, "split": "val"}
        ],
    }
    (tmp_path / "slow.json").write_text(json.dumps(config))
    env = {**os.environ, "PYOPENGL_PLATFORM": os.environ.get("PYOPENGL_PLATFORM", "osmesa")}
    proc = subprocess.Popen(
        [*NEURALAO, "dataset", "slow.json", "--out", "ds", "--no-progress"],
        cwd=tmp_path,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    time.sleep(6.0)  # in the work: modules loaded, the first views rendered and traced
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130 and err == "neuralao dataset: interrupted (Ctrl-C)\n", (
        proc.returncode,
        err,
    )

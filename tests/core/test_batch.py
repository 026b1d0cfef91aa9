"""Batch runs: inputs, settings, per-take outcomes on mixed folders, no partial outputs, kill and rerun."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT, data_path
from helpers import synthetic_takes as _synthetic
from mocap_autolabel.batch import BatchSettings, find_takes, run_batch
from mocap_autolabel.cli import main
from mocap_autolabel.core.formats.c3d import write_c3d
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.synth.generate import synthesize
from mocap_autolabel.core.take import read_take


def test_inputs_are_files_folders_and_globs_without_name_clashes(tmp_path):
    _synthetic(tmp_path / "a", 1)
    _synthetic(tmp_path / "a" / "deeper", 1)
    _synthetic(tmp_path / "b", 1)
    (tmp_path / "a" / "notes.txt").write_text("not a take")
    found = find_takes([str(tmp_path / "a"), str(tmp_path / "b" / "*.c3d"), str(tmp_path / "b" / "synth0.c3d")])
    names = sorted(name for _, name in found)
    assert names == sorted(["synth0", os.path.join("deeper", "synth0"), "synth0-2"])  # b/synth0 once


def test_settings_file_and_flags(tmp_path):
    cfg = tmp_path / "studio.toml"
    cfg.write_text('[batch]\nlayout = "glove13"\njobs = 2\nconfident = 0.9\ncalibration = "calib/p1.json"\n')
    s = BatchSettings.from_toml(str(cfg))
    assert (s.layout, s.jobs, s.confident) == ("glove13", 2, 0.9)
    assert s.calibration == str(tmp_path / "calib" / "p1.json")
    (tmp_path / "bad.toml").write_text("layuot = 'han19'\n")
    with pytest.raises(ValueError, match="unknown setting.*layuot"):
        BatchSettings.from_toml(str(tmp_path / "bad.toml"))
    assert main(["batch", str(tmp_path), "-o", str(tmp_path / "out"), "--config", str(tmp_path / "bad.toml")]) == 2
    assert main(["batch", str(tmp_path / "nowhere"), "-o", str(tmp_path / "out")]) == 2  # no such input
    assert main(["batch", str(tmp_path / "*.c3d"), "-o", str(tmp_path / "out")]) == 2  # no takes


def _outputs_complete(out: Path) -> None:
    """Every visible file is whole: reports parse, labeled C3Ds read back."""
    for path in out.rglob("*"):
        if path.is_dir() or path.name.startswith("."):
            continue
        if path.suffix == ".json":
            json.loads(path.read_text())
        elif path.suffix == ".c3d":
            assert read_take(path).n_frames > 0


def test_mixed_folder_gives_the_right_outcome_per_file(tmp_path, capsys):
    takes = tmp_path / "takes"
    _synthetic(takes, 2)
    for name in ("Vicon.c3d", "Kistler.c3d"):
        (takes / name).write_bytes(data_path("c3d", "ezc3d-testFiles", name).read_bytes())
    good = (takes / "synth0.c3d").read_bytes()
    (takes / "truncated.c3d").write_bytes(good[: len(good) // 3])
    (takes / "noise.c3d").write_bytes(os.urandom(4000))
    (takes / "empty.trc").write_text("")
    out = tmp_path / "out"
    code = main(["batch", str(takes), "-o", str(out), "--config", os.devnull, "--quiet"])
    assert code == 1
    summary = json.loads((out / "summary.json").read_text())
    status = {t["name"]: t["status"] for t in summary["takes_detail"]}
    assert status == {"synth0": "ok", "synth1": "ok", "Vicon": "failed", "Kistler": "failed", "truncated": "failed",
                      "noise": "failed", "empty": "failed"}
    errors = {t["name"]: t["error"] for t in summary["takes_detail"]}
    assert "no hand found" in errors["Vicon"] and "no marker samples" in errors["Kistler"]
    assert "truncated" in errors["truncated"] and errors["noise"] and errors["empty"]
    assert all(str(takes) in e for e in errors.values() if e)  # each names its file
    for name in ("synth0", "synth1"):
        report = json.loads((out / f"{name}.report.json").read_text())
        assert report["status"] == "ok" and report["summary"]["labeled_segments"] > 0
        assert read_take(out / f"{name}.labeled.c3d").names[:3] == load_layout("han19").names[:3]
    assert not (out / "Vicon.labeled.c3d").exists()
    assert (out / "summary.csv").read_text().count("\n") == 8
    _outputs_complete(out)
    printed = capsys.readouterr().out
    assert "2 ok, 5 failed, 0 skipped" in printed


def test_a_take_of_another_layout_is_flagged_or_refused_with_the_right_layout(tmp_path, capsys):
    takes = tmp_path / "takes"
    takes.mkdir()
    # A glove13 take whose markers pass for half a han19 hand in most frames (0.57-0.79 of them,
    # whatever the stride; most glove13 takes are refused as no hand): labeled, with a warning.
    write_c3d(synthesize(load_layout("glove13"), 300, seed=4).take, takes / "glove.c3d")
    out = tmp_path / "out"
    assert main(["batch", str(takes), "-o", str(out), "--config", os.devnull, "--quiet"]) == 0  # han19
    row = json.loads((out / "summary.json").read_text())["takes_detail"][0]
    assert row["status"] == "ok" and "is this a glove13 take?" in row["warning"]
    assert "is this a glove13 take?" in json.loads((out / "glove.report.json").read_text())["warning"]
    assert "warning" in (out / "summary.csv").read_text().splitlines()[0]
    printed = capsys.readouterr().out
    assert "ok !" in printed and "! glove: only" in printed
    write_c3d(synthesize(load_layout("han19"), 300, seed=1).take, takes / "glove.c3d")  # now a han19 take
    assert main(["batch", str(takes), "-o", str(out), "--config", os.devnull, "--quiet", "--layout", "glove13",
                 "--force"]) == 1
    row = json.loads((out / "summary.json").read_text())["takes_detail"][0]
    assert "no hand found" in row["error"] and "'han19' fits better: use --layout han19" in row["error"]


def test_killed_run_resumes_without_redoing_finished_takes(tmp_path):
    takes = tmp_path / "takes"
    _synthetic(takes, 4, frames=1500)
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "mocap_autolabel", "batch", str(takes), "-o", str(out), "--json-progress"]
    env = dict(os.environ, PYTHONPATH=str(ROOT / "addon"))
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, env=env)
    done_before = []
    for line in proc.stderr:
        event = json.loads(line)
        if event["event"] == "done":
            done_before.append(event["name"])
            proc.send_signal(signal.SIGKILL)  # in the middle of the next take
            break
    proc.wait(timeout=60)
    assert done_before and not (out / "summary.json").exists()
    _outputs_complete(out)
    rerun = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=600)
    assert rerun.returncode == 0, rerun.stderr
    events = [json.loads(line) for line in rerun.stderr.splitlines() if line.startswith("{")]
    skipped = sorted(e["name"] for e in events if e["event"] == "skipped")
    redone = sorted(e["name"] for e in events if e["event"] == "done")
    assert skipped == sorted(done_before)
    assert sorted(skipped + redone) == [f"synth{i}" for i in range(4)]
    assert not [p for p in out.iterdir() if ".partial" in p.name]
    forced = subprocess.run(cmd[:-1] + ["--force", "--quiet"], capture_output=True, text=True, env=env, timeout=600)
    assert forced.returncode == 0 and "4 ok, 0 failed, 0 skipped" in forced.stdout


def test_two_jobs_give_the_same_outputs(tmp_path):
    takes = tmp_path / "takes"
    _synthetic(takes, 2)
    one = run_batch([str(takes)], str(tmp_path / "one"), BatchSettings(), progress="none")
    two = run_batch([str(takes)], str(tmp_path / "two"), BatchSettings(jobs=2), progress="none")
    assert one["ok"] == two["ok"] == 2
    for name in ("synth0", "synth1"):
        a = read_take(tmp_path / "one" / f"{name}.labeled.c3d")
        b = read_take(tmp_path / "two" / f"{name}.labeled.c3d")
        assert a.names == b.names and (a.valid == b.valid).all()


def test_an_output_folder_inside_the_inputs_is_not_labeled_again(tmp_path):
    """``batch in -o in`` run twice labeled its own outputs (``take.labeled.labeled.c3d``) the second time."""
    takes = tmp_path / "takes"
    _synthetic(takes, 2)
    first = run_batch([str(takes)], str(takes), BatchSettings(), progress="none")
    again = run_batch([str(takes)], str(takes), BatchSettings(), progress="none")
    assert first["ok"] == 2 and again["ok"] == 2 and again["skipped"] == 2
    assert not [p.name for p in takes.iterdir() if ".labeled." in p.name and not p.name.endswith("1.labeled.c3d")
                and p.name != "synth0.labeled.c3d"]
    # A labeled take named on its own is still a take (the user asked for it).
    named = run_batch([str(takes / "synth0.labeled.c3d")], str(tmp_path / "out"), BatchSettings(), progress="none")
    assert named["ok"] == 1


def test_a_take_whose_input_left_the_batch_is_still_listed_with_its_outputs(tmp_path):
    """Outputs of a take whose input a rerun was not given stayed in the folder, unlisted by the summary."""
    from mocap_autolabel.batch import format_table

    takes, out = tmp_path / "takes", tmp_path / "out"
    _synthetic(takes, 2)
    assert run_batch([str(takes)], str(out), BatchSettings(), progress="none")["ok"] == 2
    (takes / "synth1.c3d").unlink()
    summary = run_batch([str(takes)], str(out), BatchSettings(), progress="none")
    assert summary["takes"] == 1 and summary["earlier"] == 1
    (row,) = summary["earlier_detail"]
    assert row["name"] == "synth1" and row["status"] == "earlier run"
    assert all((out / f).exists() for f in row["outputs"])
    assert "synth1,earlier run," in (out / "summary.csv").read_text()
    assert "also in the folder from earlier runs (their inputs are not among this run's): synth1" in \
        format_table(summary)


def test_batch_runs_as_a_blender_script(tmp_path):
    """The way `blender -b --python-exit-code 1 -P addon/mocap_autolabel/cli.py -- batch ...` runs it."""
    takes = tmp_path / "takes"
    _synthetic(takes, 2)
    script = ROOT / "addon" / "mocap_autolabel" / "cli.py"
    done = subprocess.run([sys.executable, str(script), "--", "batch", str(takes), "-o", str(tmp_path / "out"),
                           "--jobs", "2", "--quiet"], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert "2 ok, 0 failed, 0 skipped" in done.stdout


def test_two_hands_forced_on_a_one_hand_take_label_the_one_it_holds_and_say_so(tmp_path):
    takes = tmp_path / "takes"
    takes.mkdir()
    write_c3d(synthesize(load_layout("han19"), 300, seed=9).take, takes / "forced.c3d")
    forced = run_batch([str(takes / "forced.c3d")], str(tmp_path / "forced"), BatchSettings(hands="2"),
                       progress="none")
    assert forced["ok"] == 1 and "two hands were forced, one was found" in forced["takes_detail"][0]["warning"]


def _on_disk(out: Path) -> list[str]:
    """The files of takes in a batch folder (not its summaries), relative to it."""
    return sorted(str(p.relative_to(out)) for p in out.rglob("*")
                  if p.is_file() and p.name not in ("summary.json", "summary.csv", "index.html"))


def _listed(summary: dict) -> list[str]:
    return sorted(f for row in summary["takes_detail"] for f in row["outputs"])


def test_resume_knows_a_take_by_its_input_and_the_settings_that_made_it(tmp_path):
    """Two inputs of one name keep distinct output names across runs; a changed input or changed settings
    is done again (issue 47: A was skipped as B's take, and --layout glove13 skipped han19's takes)."""
    a, b = tmp_path / "A" / "take.c3d", tmp_path / "B" / "take.c3d"
    for seed, path in ((1, a), (2, b)):
        path.parent.mkdir()
        write_c3d(synthesize(load_layout("han19"), 200, seed=seed).take, path)
    out = tmp_path / "out"

    def batch(*paths, **settings):
        summary = run_batch([str(p) for p in paths], str(out), BatchSettings(**settings), progress="none")
        names = [r["name"] for r in summary["takes_detail"]]
        # the reports list exactly the takes' files
        assert _listed(summary) == [f for f in _on_disk(out) if any(f.startswith(n + ".") for n in names)]
        return {r["name"]: (r["file"], r["skipped"]) for r in summary["takes_detail"]}

    assert batch(b) == {"take": (str(b), False)}
    assert batch(a, b) == {"take": (str(b), True), "take-2": (str(a), False)}  # A labeled, under a name of its own
    assert batch(a) == {"take-2": (str(a), True)}  # A alone keeps its name, and B's outputs are B's
    assert json.loads((out / "take.report.json").read_text())["file"] == str(b)
    before = (out / "take-2.labeled.c3d").read_bytes()
    assert read_take(out / "take-2.labeled.c3d").n_frames == read_take(a).n_frames
    os.utime(a, ns=(1, 1))  # a touch changes no byte: not done again (its content is hashed)
    assert batch(a, b) == {"take": (str(b), True), "take-2": (str(a), True)}
    write_c3d(synthesize(load_layout("han19"), 240, seed=3).take, b)  # B's content changed at its path
    assert batch(a, b) == {"take": (str(b), False), "take-2": (str(a), True)}
    assert read_take(out / "take.labeled.c3d").n_frames == 240
    assert batch(a, b, confident=0.9) == {"take": (str(b), False), "take-2": (str(a), False)}  # new settings
    assert batch(a, b, confident=0.9, jobs=2, force=False) == {"take": (str(b), True), "take-2": (str(a), True)}
    # another layout: both done again (refused as glove13 takes, so no outputs are left beside their reports)
    glove = run_batch([str(a), str(b)], str(out), BatchSettings(layout="glove13"), progress="none")
    assert (glove["failed"], glove["skipped"]) == (2, 0)
    assert _on_disk(out) == ["take-2.report.json", "take.report.json"] == _listed(glove)
    assert (out / "take-2.labeled.c3d").exists() is False and before


def test_a_rerun_with_other_output_flags_leaves_exactly_its_outputs(tmp_path, bpy_module):
    """--fbx, then --html, then neither: each run's take outputs are exactly what it makes, all listed."""
    _synthetic(tmp_path / "takes", 1, frames=200)
    out = tmp_path / "out"
    for flags, files in ((dict(fbx=True), ["synth0.fbx", "synth0.labeled.c3d", "synth0.report.json"]),
                         (dict(html=True), ["synth0.labeled.c3d", "synth0.report.html", "synth0.report.json"]),
                         ({}, ["synth0.labeled.c3d", "synth0.report.json"])):
        summary = run_batch([str(tmp_path / "takes")], str(out), BatchSettings(**flags), progress="none")
        assert summary["ok"] == 1 and summary["skipped"] == 0, (flags, summary["takes_detail"])
        assert _on_disk(out) == files == _listed(summary), flags
        assert (out / "index.html").exists() == bool(flags.get("html"))
        report = json.loads((out / "synth0.report.json").read_text())
        assert sorted(report["outputs"].values()) == [f for f in files if not f.endswith(".json")]


# --- the batch ETA (issue 48): a fixed cost per take plus a cost per byte, takes in flight, over the workers ---

#: A synthetic batch: file sizes (bytes) of mixed takes, each costing a fixed 20 s (process start, model load,
#: calibration, writing the .blend and FBX) plus 5 s per MB, within +-10 %.
ETA_SIZES = [int(mb * 1e6) for mb in (0.2, 6, 0.5, 3, 8, 0.3, 1, 5, 0.4, 2, 0.7, 4)]


def _schedule(sizes: list[int], jobs: int, warmup: float = 0.0, seed: int = 4) -> list[tuple[float, float, str, float]]:
    """The true run of the synthetic batch in ``jobs`` workers (takes in order, each to the first worker
    free; a worker's first take also pays ``warmup`` seconds for the worker's start): ``(start, end, name,
    seconds)`` per take, by end."""
    import heapq
    import random

    rng = random.Random(seed)
    free = [(0.0, w) for w in range(jobs)]
    started = set()
    out = []
    for i, size in enumerate(sizes):
        start, worker = heapq.heappop(free)
        seconds = (20.0 + 5e-6 * size) * rng.uniform(0.9, 1.1) + (0.0 if worker in started else warmup)
        started.add(worker)
        heapq.heappush(free, (start + seconds, worker))
        out.append((start, start + seconds, f"t{i}", seconds))
    return sorted(out, key=lambda r: r[1])


class _Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


@pytest.mark.parametrize("warmup", [0.0, 8.0])
@pytest.mark.parametrize("jobs", [1, 2, 3])
@pytest.mark.parametrize("order", ["mixed", "biggest first", "smallest first"])
def test_the_eta_is_honest_for_mixed_sizes_a_fixed_cost_and_takes_in_flight(order, jobs, warmup):
    """After each take done, the batch ETA is within the truth's range: the time the last take really ends,
    from then, as a factor either way (5 s added to both, a quarter of the fixed cost, for the last seconds).
    One take done cannot tell its fixed cost from its cost per byte: within 3.5 (its time scaled by the square
    root of the sizes' ratio is off by at most the root of the ratio, 6.3 here); after 2 or 3, within 3; from
    the 4th on within 1.7 and 1.3 on average, and within 1.25 in the mixed order (a folder's takes by name).
    The bytes left at the rate of the takes done (what it was) is off by 13 after the first take in the mixed
    order and by 8 in the later ones taking the smallest first (it said 00:02 with minutes left): it fails."""
    import io

    from mocap_autolabel.batch import Progress

    sizes_in_order = {"mixed": ETA_SIZES, "biggest first": sorted(ETA_SIZES, reverse=True),
                      "smallest first": sorted(ETA_SIZES)}[order]
    sizes = {f"t{i}": s for i, s in enumerate(sizes_in_order)}
    run = _schedule(sizes_in_order, jobs, warmup)
    end = max(r[1] for r in run)
    # One worker: the batch says when each take starts (a pool and a cluster do not).
    events = sorted([(t_end, 1, name, seconds) for _, t_end, name, seconds in run]
                    + ([(t_start, 0, name, 0.0) for t_start, _, name, _ in run] if jobs == 1 else []))
    clock = _Clock()
    bar = Progress(sizes, "json", jobs, stream=io.StringIO(), clock=clock)
    bar.begin(list(sizes))
    assert bar.eta() != bar.eta()  # nothing done: no ETA (NaN), rather than a made-up one
    done, later = 0, []
    for when, is_done, name, seconds in events:
        clock.now = when
        if not is_done:
            bar.event("start", name=name)
            continue
        bar.event("done", name=name, seconds=seconds)
        done += 1
        truth, eta = end - when, bar.eta()
        if done == len(run):
            assert eta == 0.0
            continue
        off = max((eta + 5.0) / (truth + 5.0), (truth + 5.0) / (eta + 5.0))
        limit = 3.5 if done == 1 else 3.0 if done <= 3 else 1.25 if order == "mixed" else 1.7
        assert off <= limit, (done, name, round(eta, 1), round(truth, 1))
        if done > 3:
            later.append(off)
    assert sum(later) / len(later) <= 1.3
    # The fit knows a take's time by the end: 20 s and 5 s per MB (25 s for 1 MB, 60 s for 8 MB).
    assert bar.seconds(1_000_000) == pytest.approx(25.0, rel=0.15)
    assert bar.seconds(8_000_000) == pytest.approx(60.0, rel=0.15)


def test_the_eta_of_takes_in_flight_runs_down_and_never_goes_negative():
    from mocap_autolabel.batch import Progress

    clock = _Clock()
    bar = Progress({"a": 1_000_000, "b": 1_000_000, "c": 4_000_000}, "none", jobs=2, clock=clock)
    bar.begin(["a", "b", "c"])
    clock.now = 30.0
    bar.event("done", name="a", seconds=30.0)  # b has run 30 s too; c starts now
    # One take done: its time scaled by the square root of the sizes: b (1 MB) 30 s, c (4 MB) 60 s.
    assert bar.expected("b") == pytest.approx(30.0) and bar.expected("c") == pytest.approx(60.0)
    assert bar.eta() == pytest.approx(60.0)  # c, just started, is the last; b is due now
    clock.now = 60.0
    assert bar.eta() == pytest.approx(30.0)  # in flight: what is left of it, not its whole time again
    clock.now = 500.0
    assert bar.eta() == 0.0  # late: nothing left to say, never negative
    bar.event("done", name="c", seconds=470.0)
    bar.event("done", name="b", seconds=470.0)
    assert bar.eta() == 0.0


def test_the_bar_and_json_lines_say_the_eta(tmp_path):
    import io
    import re

    from mocap_autolabel.batch import Progress

    sizes = {"small": 100_000, "big": 5_000_000, "old": 300_000}
    for mode in ("bar", "json"):
        clock, out = _Clock(), io.StringIO()
        bar = Progress(sizes, mode, jobs=1, stream=out, clock=clock)
        bar.event("skipped", name="old")  # before the takes to run are known: no ETA yet
        bar.begin(["small", "big"])
        bar.event("start", name="small")
        clock.now = 12.0
        bar.event("done", name="small", seconds=11.5)
        bar.event("start", name="big")
        clock.now = 20.0
        bar.event("failed", name="big", seconds=8.0, error="bad file")
        bar.event("end", name="1 ok, 1 failed, 1 skipped")
        lines = out.getvalue().splitlines()
        assert len(lines) == 6
        if mode == "json":
            events = [json.loads(line) for line in lines]
            assert [e["event"] for e in events] == ["skipped", "start", "done", "start", "failed", "end"]
            assert "eta_s" not in events[0] and "eta_s" not in events[1] and "take_eta_s" not in events[1]
            # One take done in 12 s (its span from its start, not the 11.5 s it says): big, 50 times its size,
            # 12 x sqrt(50) = 84.9 s.
            assert events[2]["eta_s"] == pytest.approx(84.9) and events[3]["take_eta_s"] == pytest.approx(84.9)
            assert events[4]["eta_s"] == 0 and events[5]["eta_s"] == 0
            assert events[4]["done"] == 3 and events[4]["total"] == 3 and events[4]["error"] == "bad file"
        else:
            etas = [re.search(r"ETA (\S+)", line).group(1) for line in lines]
            assert etas == ["--:--", "--:--", "01:25", "01:25", "00:00", "00:00"]
            assert lines[3].endswith("working on big (about 01:25)")
            assert lines[4].startswith("[########################] 3/3") and "FAILED big in 00:08: bad file" in lines[4]


def test_a_performers_labeled_take_fits_gmm_for_every_take_as_label_fit_does(tmp_path, capsys):
    from mocap_autolabel.core.labeling import labeled_take, segments_from_runs
    from mocap_autolabel.core.take import Take

    layout = load_layout("tips5_hand3")

    def labeled(seed: int, frames: slice):
        """One synthetic performer's take cut to ``frames``, labeled with its truth."""
        s = synthesize(layout, 700, seed=seed)
        take = Take(positions=s.take.positions[frames], names=s.take.names, rate=s.take.rate)
        truth = segments_from_runs(layout.names, s.labels[frames], take.valid, {})
        return take, labeled_take(take, truth)

    fit = tmp_path / "performer.c3d"
    write_c3d(labeled(5, slice(0, 400))[1], fit)
    takes = tmp_path / "takes"
    takes.mkdir()
    write_c3d(labeled(5, slice(400, 700))[0], takes / "a.c3d")  # the same performer, raw
    out, alone, without = tmp_path / "out", tmp_path / "alone.c3d", tmp_path / "rom.c3d"
    flags = ["--config", os.devnull, "--quiet", "--layout", "tips5_hand3", "--method", "gmm"]
    assert main(["batch", str(takes), "-o", str(out), *flags, "--fit", str(fit)]) == 0
    label = ["label", str(takes / "a.c3d"), "--layout", "tips5_hand3", "--method", "gmm", "--quiet", "-o"]
    assert main([*label, str(alone), "--fit", str(fit)]) == 0
    assert (out / "a.labeled.c3d").read_bytes() == alone.read_bytes()  # the same fit, the same labels
    main([*label, str(without)])
    assert not without.exists() or without.read_bytes() != alone.read_bytes()  # the range of motion labels otherwise
    capsys.readouterr()
    assert main(["batch", str(takes), "-o", str(out), *flags, "--fit", str(fit)]) == 0
    assert "1 skipped" in capsys.readouterr().out  # the same performer's take: nothing to redo
    write_c3d(labeled(7, slice(0, 400))[1], fit)  # another performer's: every take is labeled again
    main(["batch", str(takes), "-o", str(out), *flags, "--fit", str(fit)])
    assert "0 skipped" in capsys.readouterr().out
    assert main(["batch", str(takes), "-o", str(out), *flags, "--fit", str(tmp_path / "none.c3d")]) == 2
    assert "--fit" in capsys.readouterr().err

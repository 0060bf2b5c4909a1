"""The benchmark's same-run yardstick: a reference time, and figures divided by it the right way round."""

from __future__ import annotations

import pytest

from woody_tools.benchmarks.suite import reference_ms, with_reference


def test_reference_workload_takes_measurable_time():
    assert 0.1 < reference_ms(repeats=3) < 5000.0


def test_times_are_divided_by_the_reference_and_rates_multiplied():
    out = with_reference({"render_top_ms": 4.0, "rtf": 1.5, "sweep_evals_per_min": 300.0, "frames": 300}, 2.0)
    assert out["render_top_ms_ref"] == pytest.approx(2.0)  # two reference workloads
    assert out["rtf_ref"] == pytest.approx(0.003)  # sim seconds per reference workload
    assert out["sweep_evals_per_min_ref"] == pytest.approx(0.6)
    assert "frames_ref" not in out and list(out)[:2] == ["render_top_ms", "render_top_ms_ref"]


def test_a_small_rate_per_reference_is_printed_to_four_significant_digits(monkeypatch, capsys):
    import argparse

    from woody_tools.commands import bench as command

    monkeypatch.setattr(command, "reference_ms", lambda: 1.836)
    monkeypatch.setattr(command, "bench_graph", lambda **line: {"woody_run_rtf": 0.73, "verdicts": 70})
    assert command.run(argparse.Namespace(target="graph", json_path=None, lanes=3, speed_fpm=100.0, live=False,
                                          line=None, lane_pitch=None, spacing=None, physics_workers=None)) == 0
    printed = dict(line.split() for line in capsys.readouterr().out.splitlines())
    assert printed == {"reference_ms": "1.836", "woody_run_rtf": "0.73", "woody_run_rtf_ref": "0.00134",
                       "verdicts": "70"}


def test_the_line_to_benchmark_is_checked_like_woody_runs(capsys):
    import argparse

    from woody_tools.commands import bench as command

    parser = argparse.ArgumentParser(prog="woody bench")
    command.add_arguments(parser)
    args = parser.parse_args(["sim", "--lanes", "6", "--speed-fpm", "130"])
    assert (args.lanes, args.speed_fpm) == (6, 130.0)
    for bad in (["--lanes", "7"], ["--lanes", "2.5"], ["--speed-fpm", "0"]):
        with pytest.raises(SystemExit):
            parser.parse_args(["graph", *bad])
        assert "woody bench: error: argument" in capsys.readouterr().err


def test_the_graph_runs_the_crowded_line_and_the_physics_workers_it_is_given(monkeypatch, capsys):
    import argparse

    from woody_tools.commands import bench as command

    given = {}
    monkeypatch.setattr(command, "bench_graph", lambda **line: given.update(line) or {"woody_run_rtf": 0.3})
    parser = argparse.ArgumentParser(prog="woody bench")
    command.add_arguments(parser)
    args = parser.parse_args(["graph", "--lanes", "6", "--speed-fpm", "130", "--line", "messy", "--lane-pitch",
                              "0.12", "--spacing", "0.26", "--physics-workers", "0"])
    assert command.run(args) == 0
    assert given["run_options"] == ["--line", "messy", "--lane-pitch", "0.12", "--spacing", "0.26",
                                    "--physics-workers", "0"]
    assert command._graph_options(parser.parse_args(["graph"])) == []

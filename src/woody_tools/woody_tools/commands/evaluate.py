"""`woody evaluate`: the live line over a grid of seeds x line conditions x lanes x speeds, one `woody run` a cell.

Each cell is a `woody run` started as its own process (its nodes on a private ROS domain it leases, so an exported
ROS_DOMAIN_ID is not passed on) into ``--out/runs/<cell>/``; a cell whose verdicts.csv exists is done and not run
again, so a grid cut short resumes where it stopped. Every option is checked, and every cell's `woody run` options
with woody run's own checks, before anything is written. The pooled counts are
:mod:`woody_experiments.live_evaluation`'s: evaluation.md, evaluation.csv and the summary table printed.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

from woody_common.line import MAX_FILLETS, MAX_LANES, MAX_SEED
from woody_experiments import live_evaluation as live
from woody_experiments.live_evaluation import Cell
from woody_tools import arguments
from woody_tools.processes import STOP, end_with_parent, entry_point

SETTINGS_FILE = "evaluate.json"
"""In --out: the settings every run there shares (FOLDER_SETTINGS); another value needs another --out."""
FOLDER_SETTINGS = ("fillets", "meshes", "k")
MAX_SEEDS = 10_000
"""Most seeds a grid takes (each is a `woody run` per condition, lanes and speed)."""
INTERRUPTED_VERDICTS = "verdicts-interrupted.csv"
"""Where a cell's verdicts.csv goes when its run was stopped by a signal: what it graded is kept, and the cell is
run again by the next call."""
HANGUP_LOG = "woody_evaluate.log"
"""In --out: what `woody evaluate` prints once its terminal has closed (SIGHUP)."""
POLL_S = 0.2
"""How often the runs in progress are looked at (s)."""


class Refused(Exception):
    """A bad option value; the message is one line (printed, exit code 2)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    conditions = "; ".join(f"{name}: {live.describe_condition(name)}" for name in live.LIVE_CONDITIONS)
    parser.add_argument("--seeds", default="1-3", metavar="SEEDS",
                        help="seeds of the runs (woody run --seed): 1-8, 1,2,3 or a mix like 1-3,7 (default 1-3)")
    parser.add_argument("--conditions", default=",".join(live.LIVE_CONDITIONS), metavar="NAMES",
                        help=f"line conditions, comma-separated (default all). {conditions}")
    parser.add_argument("--lanes", default="3", metavar="N,...",
                        help="lane counts, comma-separated, 1-6 each (default 3)")
    parser.add_argument("--speeds", default="100,130", metavar="FPM,...",
                        help="line speeds in FPM, comma-separated (default 100,130)")
    parser.add_argument("--fillets", type=int, default=24, metavar="N", help="fillets spawned per run (default 24)")
    parser.add_argument("--meshes", default="builtin", metavar="SPEC",
                        help="mesh set of every run (woody run --meshes; default builtin); the crowded and gaps "
                             "spacings are measured on it")
    parser.add_argument("--k", default="0,100", metavar="K,...",
                        help="stiffness values every run mixes, comma-separated (woody run --k; default 0,100)")
    parser.add_argument("--out", default="evaluate-out", metavar="DIR",
                        help="output folder: runs/<cell>/ per run, evaluation.md, evaluation.csv (default "
                             "evaluate-out); one --fillets, --meshes and --k per folder")
    parser.add_argument("--timeout", type=float, default=1800.0, metavar="S",
                        help="wall-clock limit of each run in seconds (woody run --timeout; default 1800)")
    parser.add_argument("--jobs", type=int, default=1, metavar="N",
                        help="runs at a time (default 1: a line is five processes, and lines side by side slow "
                             "each other down)")


def _seed_list(text: str) -> list[int]:
    """``1-8``, ``1,2,3`` or a mix (``1-3,7``) as the seeds in order, each once; a ValueError says what is wanted."""
    ranges = []
    for item in text.split(","):
        match = re.fullmatch(r"\s*(\d+)(?:\s*-\s*(\d+))?\s*", item)
        low, high = (int(match.group(1)), int(match.group(2) or match.group(1))) if match else (0, -1)
        if not 0 <= low <= high <= MAX_SEED:
            raise ValueError(f"--seeds must be like 1-8 or 1,2,3 with seeds 0..{MAX_SEED}, got '{text}'")
        ranges.append((low, high))
    if sum(high - low + 1 for low, high in ranges) > MAX_SEEDS:
        raise ValueError(f"--seeds must name at most {MAX_SEEDS} seeds, got '{text}'")
    return list(dict.fromkeys(seed for low, high in ranges for seed in range(low, high + 1)))


def _listed(parse, option: str, text: str) -> list:
    """A comma-separated option through an argparse type of woody_tools.arguments, its refusal as one line."""
    try:
        return parse(text)
    except argparse.ArgumentTypeError as exc:
        raise Refused(f"{option}: {exc}") from None


LANE_COUNTS = arguments.number_list(lambda n: n.is_integer() and 1 <= n <= MAX_LANES,
                                    f"every lane count must be a whole number 1..{MAX_LANES}")


def _grid(args: argparse.Namespace) -> list[Cell]:
    """The cells of the options (sets ``args.k``), or `Refused` naming the first bad one."""
    try:
        seeds = _seed_list(args.seeds)
    except ValueError as exc:
        raise Refused(str(exc)) from None
    conditions = [c.strip() for c in args.conditions.split(",") if c.strip()]
    unknown = [c for c in conditions if c not in live.LIVE_CONDITIONS]
    if not conditions or unknown:
        raise Refused(f"--conditions must be among {','.join(live.LIVE_CONDITIONS)}, got '{args.conditions}'")
    lanes = [int(n) for n in _listed(LANE_COUNTS, "--lanes", args.lanes)]
    speeds = _listed(arguments.LINE_SPEEDS, "--speeds", args.speeds)
    args.k = _listed(arguments.STIFFNESSES, "--k", args.k)
    if not args.timeout > 0:
        raise Refused(f"--timeout must be a positive number of seconds, got {args.timeout:g}")
    if args.jobs < 1:
        raise Refused(f"--jobs must be at least 1, got {args.jobs}")
    return live.grid(seeds, list(dict.fromkeys(conditions)), list(dict.fromkeys(lanes)), list(dict.fromkeys(speeds)))


def _condition_options(args: argparse.Namespace, cells: list[Cell]) -> tuple[dict[str, list[str]], list[str]]:
    """The `woody run` options of each condition on the mesh set, and the set's notes (meshes skipped or
    converted)."""
    from woody_sim.meshes import checked_mesh_set

    try:
        meshes, notes = checked_mesh_set(args.meshes)
    except ValueError as exc:
        raise Refused(f"--meshes: {exc}") from None
    conditions = dict.fromkeys(c.condition for c in cells)
    return {c: live.condition_options(c, meshes) for c in conditions}, notes


def _run_arguments(cell: Cell, args: argparse.Namespace, options: dict[str, list[str]], out: Path) -> list[str]:
    """The `woody run` arguments of a cell (after ``woody run``)."""
    return ["--lanes", str(cell.lanes), "--speed-fpm", f"{cell.speed_fpm:g}", "--seed", str(cell.seed),
            "--fillets", str(args.fillets), "--meshes", args.meshes, "--k", *(f"{k:g}" for k in args.k),
            *options[cell.condition], "--timeout", f"{args.timeout:g}", "--out", str(live.cell_folder(out, cell)),
            "--force"]


def _check_with_woody_run(cells: list[Cell], args: argparse.Namespace, options: dict[str, list[str]]) -> None:
    """Every condition, lane count and speed through woody run's own checks, so no cell is refused mid-grid."""
    from woody_tools.commands import run as woody_run
    from woody_tools.line_run import RunRefused

    parser = argparse.ArgumentParser(prog="woody run")
    woody_run.add_arguments(parser)
    for cell in {c.group: c for c in cells}.values():
        try:
            woody_run.checked(parser.parse_args(_run_arguments(cell, args, options, Path(args.out))))
        except RunRefused as exc:
            raise Refused(f"woody run refuses the {cell.condition} line at {cell.lanes} lanes and "
                          f"{cell.speed_fpm:g} FPM: {exc}") from None


def _check_out(args: argparse.Namespace) -> dict[str, object]:
    """The folder's settings (SETTINGS_FILE) for these options; `Refused` when --out cannot be a folder or holds
    runs of other settings."""
    out = Path(args.out)
    problem = arguments.out_folder_problem(out)
    if problem:
        raise Refused(f"--out {out}: {problem}")
    settings = {name: getattr(args, name) for name in FOLDER_SETTINGS}
    path = out / SETTINGS_FILE
    before = json.loads(path.read_text()) if path.is_file() else settings
    for name in FOLDER_SETTINGS:
        if before.get(name) != settings[name]:
            raise Refused(f"--out {out} holds runs with --{name} {_option_text(before.get(name))}; use another --out "
                          f"for --{name} {_option_text(settings[name])}")
    return settings


def _option_text(value: object) -> str:
    return ",".join(f"{v:g}" for v in value) if isinstance(value, list) else str(value)


def _checked(args: argparse.Namespace) -> tuple[list[Cell], dict[str, list[str]], dict[str, object], list[str]]:
    """The grid, each condition's woody run options, the folder's settings and the mesh notes; `Refused` first."""
    cells = _grid(args)
    if not 1 <= args.fillets <= MAX_FILLETS:
        raise Refused(f"--fillets must be 1..{MAX_FILLETS}, got {args.fillets}")
    options, notes = _condition_options(args, cells)
    settings = _check_out(args)
    _check_with_woody_run(cells, args, options)
    return cells, options, settings, notes


class CellRun:
    """One cell's `woody run` as a child process: its own process group (a Ctrl-C reaches `woody evaluate`, which
    passes it on) and the parent-death signal, its output in the cell's RUN_LOG."""

    def __init__(self, cell: Cell, command: list[str], out: Path) -> None:
        self.cell, self.command, self.out = cell, command, out
        folder = live.cell_folder(out, cell)
        folder.mkdir(parents=True, exist_ok=True)
        self.log = open(folder / live.RUN_LOG, "w")
        env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}
        env["PYTHONUNBUFFERED"] = "1"
        self.started = time.monotonic()
        self.process = subprocess.Popen(command, stdout=self.log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                        env=env, start_new_session=True, preexec_fn=end_with_parent(os.getpid()))
        self.signalled = False

    def pass_on(self, signum: int) -> None:
        """Stop the run as that signal stops `woody run`: the line ends and what it graded is written."""
        if not self.signalled and self.process.poll() is None:
            self.process.send_signal(signum)
            self.signalled = True

    def finish(self) -> str:
        """Record the ended run (RUN_RECORD); a stopped run's verdicts.csv goes aside. One line saying how it went."""
        code = self.process.returncode
        self.log.close()
        live.write_run_record(self.out, self.cell, self.command, code, time.monotonic() - self.started)
        folder = live.cell_folder(self.out, self.cell)
        verdicts, stopped = folder / live.VERDICTS, code < 0 or code >= 128
        if stopped and verdicts.exists():
            verdicts.replace(folder / INTERRUPTED_VERDICTS)
            return f"{self.cell.name}: stopped (exit {code}); what it graded is in {folder / INTERRUPTED_VERDICTS}"
        if not verdicts.exists():
            return (f"{self.cell.name}: {'stopped' if stopped else 'failed'} (exit {code}), no verdicts.csv: "
                    f"{_last_line(folder / live.RUN_LOG)}")
        how = "done" if code == 0 else f"ended with exit {code}: {_last_line(folder / live.RUN_LOG)}"
        return f"{self.cell.name}: {how}, {time.monotonic() - self.started:.0f} s"


def _last_line(path: Path) -> str:
    lines = [line for line in path.read_text(errors="replace").splitlines() if line.strip()]
    return lines[-1] if lines else f"nothing in {path}"


def _run_cells(todo: list[Cell], done: int, total: int, args: argparse.Namespace,
               options: dict[str, list[str]]) -> None:
    """Run the cells, ``--jobs`` at a time, until all ended or a stop signal ended the ones running."""
    from tqdm import tqdm

    out, queue, running = Path(args.out), list(todo), []
    woody = entry_point("woody")
    with tqdm(total=total, initial=done, unit="run", desc="evaluate", file=sys.stderr, dynamic_ncols=True,
              disable=None) as bar:
        while queue or running:
            while queue and len(running) < args.jobs and STOP.signum is None:
                cell = queue.pop(0)
                running.append(CellRun(cell, [woody, "run", *_run_arguments(cell, args, options, out)], out))
            if STOP.signum is not None:
                queue.clear()
                for run in running:
                    run.pass_on(STOP.signum)
            for run in [r for r in running if r.process.poll() is not None]:
                running.remove(run)
                bar.update(1)
                tqdm.write(f"woody evaluate: {run.finish()}", file=sys.stderr)
            time.sleep(POLL_S)


def _settings_table(args: argparse.Namespace, options: dict[str, list[str]]) -> dict[str, object]:
    """evaluation.md's settings: the grid and each condition's woody run options."""
    table = {"seeds": args.seeds, "lanes": args.lanes, "line speeds (FPM)": args.speeds,
             "fillets per run": args.fillets, "meshes": args.meshes, "stiffness mix k": _option_text(args.k),
             "time-out per run (s)": f"{args.timeout:g}"}
    for name, opts in options.items():
        rule = live.SPACING_RULES.get(name)
        table[f"condition {name}"] = f"`woody run {' '.join(opts)}`" + (f" (spacing: {rule})" if rule else "")
    return table


def run(args: argparse.Namespace) -> int:
    try:
        cells, options, settings, notes = _checked(args)
    except Refused as exc:
        print(f"woody evaluate: {exc}", file=sys.stderr)
        return 2
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        (out / SETTINGS_FILE).write_text(json.dumps(settings, indent=2))
    except OSError as exc:  # a place the checks could not foresee (a read-only file system, /proc)
        print(f"woody evaluate: --out {out}: cannot write there ({exc.strerror or exc})", file=sys.stderr)
        return 2
    for note in notes:
        print(f"woody evaluate: {note}", file=sys.stderr)
    STOP.install()
    STOP.hangup_log = out / HANGUP_LOG
    todo = [c for c in cells if not live.is_done(out, c)]
    print(f"woody evaluate: {len(todo)} of {len(cells)} runs to go ({len(cells) - len(todo)} already done in "
          f"{out / live.RUNS_DIR}), {args.fillets} fillets each, {args.jobs} at a time", file=sys.stderr, flush=True)
    _run_cells(todo, len(cells) - len(todo), len(cells), args, options)
    md, csv_path, summary = live.write_evaluation(out, cells, _settings_table(args, options))
    print("\n".join(summary))
    print(f"\nevaluation: {md}\nrows: {csv_path}")
    if STOP.signum is not None:
        return 128 + STOP.signum
    failed = [c for c in cells if not live.is_done(out, c) or (live.run_record(out, c) or {}).get("exit_code")]
    return 1 if failed else 0

"""Bad meshes as users bring them, through `woody run`, `woody meshes stats`, `woody sweep`, `woody calibrate`,
`woody soak` and line_sim.

The files are built in a temporary folder from the project's reference meshes: a scan in millimetres
(converted, with a line saying so), the references re-saved as STL and PLY the way other tools write
them (every triangle with its own corners, a zero-area triangle; repaired), a NaN vertex, random
bytes named .stl, an empty file, a mesh a million times too large, two files with one stem. A folder
with bad meshes among good ones runs on the good ones, and every skipped or converted mesh is named
with its reason on `woody run`'s terminal and in report.md; a conversion is one line of the program
that loaded the mesh (never a Python warning); a file or folder with nothing usable, or two files
giving one name, is refused with one line and leaves nothing behind. The loader itself
(`woody_sim.meshes.load_mesh`) is unit-tested in tests/woody_sim/test_meshes.py.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from bad_input.conftest import assert_one_clear_line, run_entries, run_entry
from woody_tools.processes import lease_domain

pytestmark = pytest.mark.ros
"""Starts `woody run` (with every node), `woody meshes stats` and line_sim as processes."""

CONVERTED = "taken as mm and converted to metres"
BAD = {  # file: the reason it is skipped
    "empty.ply": "empty file",
    "garbage.stl": "not a valid STL",
    "nan.obj": "1 vertices with NaN or infinite coordinates",
}
GOOD = {"resaved.stl": "seed0001", "resaved2.ply": "seed0002", "scan_mm.stl": "seed0000"}
"""Usable files and the reference mesh each was made from."""


def save_reference(name: str, path: Path, scale: float = 1.0, unshared: bool = False) -> None:
    """A reference mesh written again; ``unshared``: every triangle with its own three corners and one
    triangle of zero area, as STL always is and as some scanners write PLY."""
    import trimesh

    from woody_sim.meshes import BUILTIN_DIR

    raw = trimesh.load(BUILTIN_DIR / f"{name}.obj", force="mesh", process=False)
    vertices, faces = raw.vertices * scale, raw.faces
    if unshared:
        vertices = np.vstack([vertices[faces].reshape(-1, 3), vertices[faces[0, :1]]])
        faces = np.vstack([np.arange(len(vertices) - 1).reshape(-1, 3), [[0, 0, len(vertices) - 1]]])
    trimesh.Trimesh(vertices, faces, process=False).export(path)


def write_bad(folder: Path) -> None:
    import trimesh

    from woody_sim.meshes import BUILTIN_DIR

    raw = trimesh.load(BUILTIN_DIR / "seed0001.obj", force="mesh", process=False)
    vertices = raw.vertices.copy()
    vertices[7] = np.nan
    trimesh.Trimesh(vertices, raw.faces, process=False).export(folder / "nan.obj")
    (folder / "garbage.stl").write_bytes(np.random.default_rng(1).bytes(3000))
    (folder / "empty.ply").write_bytes(b"")


@pytest.fixture(scope="module")
def meshes(tmp_path_factory) -> Path:
    """``mixed/``: the good and the bad files; ``bad/``: only bad ones; ``huge.stl``: a fillet 175 km long;
    ``same/``: two good files with one stem."""
    root = tmp_path_factory.mktemp("meshes")
    for folder in ("mixed", "bad"):
        (root / folder).mkdir()
        write_bad(root / folder)
    (root / "same").mkdir()
    save_reference("seed0001", root / "same" / "a.stl", unshared=True)
    save_reference("seed0002", root / "same" / "a.ply")
    save_reference("seed0001", root / "mixed" / "resaved.stl", unshared=True)
    save_reference("seed0002", root / "mixed" / "resaved2.ply", unshared=True)
    save_reference("seed0000", root / "mixed" / "scan_mm.stl", scale=1000.0, unshared=True)
    save_reference("seed0000", root / "huge.stl", scale=1e6)
    return root


def starts_a_line(text: str, start: str) -> bool:
    return any(line.startswith(start) for line in text.splitlines())


def test_a_folder_with_bad_meshes_runs_on_the_good_ones_and_names_the_rest(meshes, tmp_path):
    """Three fillets in one lane, one per usable mesh (line_sim takes them in turn): the scan in mm and both
    re-saved references are spawned and graded; every other file is named with its reason on the terminal and in
    report.md."""
    mixed, out = meshes / "mixed", tmp_path / "run"
    outcome = run_entry("woody", "run", "--lanes", "1", "--fillets", "3", "--meshes", str(mixed), "--out", str(out),
                        domain=None, timeout=300)
    assert outcome.code == 0, "\n".join(outcome.lines[-20:])
    report = (out / "report.md").read_text()
    for name, reason in BAD.items():
        assert starts_a_line(outcome.stderr, f"woody run: skipped mesh {mixed / name}: {reason}"), outcome.lines
        assert starts_a_line(report, f"- skipped mesh {mixed / name}: {reason}"), report
    converted = f"converted mesh {mixed / 'scan_mm.stl'}: 188.683 units long, {CONVERTED} (0.189 m)"
    assert f"woody run: {converted}" in outcome.lines and f"- {converted}\n" in report
    with (out / "verdicts.csv").open() as table:
        rows = list(csv.DictReader(table))
    assert sorted(row["mesh"] for row in rows) == sorted(Path(name).stem for name in GOOD)
    assert all(math.isfinite(float(row["phi"])) for row in rows), rows
    assert "Traceback" not in (out / "logs" / "line_sim.log").read_text()


def descriptor_rows(text: str) -> dict[str, list[str]]:
    """`woody meshes stats`' table: mesh name -> its descriptor columns."""
    return {words[0]: words[1:] for words in map(str.split, text.splitlines()) if len(words) == 12}


def test_meshes_stats_describes_the_repaired_and_converted_meshes_as_their_references(meshes):
    from woody_sim.meshes import BUILTIN_DIR

    mixed = meshes / "mixed"
    commands = [("woody", "meshes", "stats", str(mixed)), ("woody", "meshes", "stats", str(BUILTIN_DIR))]
    stats, builtin = run_entries(commands, None, timeout=120)
    assert stats.code == 0 and builtin.code == 0 and "Traceback" not in stats.stderr, stats.lines
    assert f"set {mixed}: 3 meshes" in stats.stdout
    for name, reason in BAD.items():
        assert starts_a_line(stats.stderr, f"woody meshes stats: skipped mesh {mixed / name}: {reason}"), stats.lines
    assert converted_lines(stats) == [f"woody meshes stats: {converted_mesh(mixed / 'scan_mm.stl')}"]
    rows, references = descriptor_rows(stats.stdout), descriptor_rows(builtin.stdout)
    for name, reference in GOOD.items():
        assert rows[Path(name).stem] == references[reference], name


def converted_mesh(path: Path) -> str:
    return f"converted mesh {path}: 188.683 units long, {CONVERTED} (0.189 m)"


def converted_lines(outcome) -> list[str]:
    """Every line saying a mesh was converted: a Python warning would show its message and the code's path."""
    return [line for line in outcome.lines if CONVERTED in line or "MeshWarning" in line]


def test_a_converted_mesh_is_one_line_of_the_program_that_loaded_it(meshes):
    """Said once by the command, not again by its workers (Dask's for the sweep, a pool's for the soak); the
    calibration refuses its held-out set after it has loaded the scan, before any cluster starts."""
    scan, bad = meshes / "mixed" / "scan_mm.stl", meshes / "bad"
    commands = {
        ("woody", "sweep", "--meshes", str(scan), "--k", "0", "--speeds", "100", "--jobs", "1", "--no-report",
         "--out", "sweep"): 0,
        ("woody", "soak", "--meshes", str(scan), "--passages", "1", "--jobs", "1"): 0,
        ("woody", "calibrate", "--meshes", str(scan), "--test-meshes", str(bad), "--out", "cal"): 2,
    }
    for (command, code), outcome in zip(commands.items(), run_entries(list(commands), None, timeout=120)):
        program = " ".join(command[:2])
        assert outcome.code == code and "Traceback" not in outcome.stderr, outcome.lines
        assert converted_lines(outcome) == [f"{program}: {converted_mesh(scan)}"], outcome.lines
    assert outcome.lines[-1].startswith(f"woody calibrate: mesh spec '{bad}': no loadable mesh")


def test_nothing_usable_is_refused_with_one_line_and_leaves_nothing(meshes):
    """A bad file given alone, a folder of bad files, two files with one name, a path that is not there, a
    malformed spec; every command that loads meshes."""
    bad, nan_file, garbage = meshes / "bad", meshes / "bad" / "nan.obj", meshes / "bad" / "garbage.stl"
    none_usable = f"mesh spec '{bad}': no loadable mesh ({bad}/"
    same = f"meshes {meshes / 'same' / 'a.ply'} and {meshes / 'same' / 'a.stl'} share the name 'a'"
    nodes = {
        ("line_sim", "--ros-args", "-p", f"meshes:={garbage}"): f"invalid parameter: {garbage}: not a valid STL",
        ("line_sim", "--ros-args", "-p", f"meshes:={nan_file}"): f"{nan_file}: {BAD['nan.obj']} (first: vertex 7)",
        ("line_sim", "--ros-args", "-p", f"meshes:={meshes / 'huge.stl'}"): "units long, not a fillet",
        ("line_sim", "--ros-args", "-p", f"meshes:={meshes / 'nothere'}"):
            f"mesh spec '{meshes / 'nothere'}': not 'builtin', 'generated:N[:SEED]', a folder or a mesh file",
        ("line_sim", "--ros-args", "-p", f"meshes:={bad}"): f"invalid parameter: {none_usable}",
        ("line_sim", "--ros-args", "-p", f"meshes:={meshes / 'same'}"): f"invalid parameter: {same}",
    }
    commands = {  # `woody run` leases a domain of its own
        ("woody", "meshes", "stats", str(nan_file)): f"{nan_file}: {BAD['nan.obj']}",
        ("woody", "meshes", "stats", "generated:0"): "mesh spec 'generated:0': N must be >= 1",
        ("woody", "meshes", "stats", str(bad)): none_usable,
        ("woody", "meshes", "stats", str(meshes / "same")): same,
        ("woody", "run", "--meshes", str(bad), "--out", "run"): f"--meshes: {none_usable}",
        ("woody", "run", "--meshes", str(meshes / "nothere"), "--out", "run"): f"mesh spec '{meshes / 'nothere'}'",
        ("woody", "run", "--meshes", str(meshes / "same"), "--out", "run"): f"--meshes: {same}",
        ("woody", "sweep", "--meshes", str(bad), "--out", "sweep"): none_usable,
        ("woody", "sweep", "--meshes", str(meshes / "same"), "--out", "sweep"): same,
        ("woody", "calibrate", "--meshes", str(bad), "--out", "cal"): none_usable,
        ("woody", "calibrate", "--loo", "--meshes", str(bad), "--out", "cal"): none_usable,
        ("woody", "soak", "--meshes", str(bad)): none_usable,
    }
    with lease_domain({}) as lease:
        outcomes = run_entries(list(nodes), lease.domain_id, timeout=60) + run_entries(list(commands), None)
    for (command, says), outcome in zip({**nodes, **commands}.items(), outcomes):
        program = "line_sim" if command[0] == "line_sim" else " ".join(command[:2 + (command[1] == "meshes")])
        line = assert_one_clear_line(outcome, program, says)
        assert not any(outcome.cwd.iterdir()), (command, list(outcome.cwd.iterdir()))
        if "no loadable mesh" in says:  # every file named with its reason
            assert all(f"{bad / name}: {reason}" in line for name, reason in BAD.items()), line

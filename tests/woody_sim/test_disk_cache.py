"""Meshes and chain models on disk: read back bit for bit, keyed by input and code; warnings are never cached away,
and a bad entry or folder is no error."""

import warnings

import numpy as np
import pytest

from woody_sim import disk_cache, line_world
from woody_sim.fillet_model import NOMINAL_MASS, build_fillet_model
from woody_sim.meshes import BUILTIN_DIR, generate_fillet, load_mesh


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv(disk_cache.ENV_VAR, str(tmp_path))
    return tmp_path


@pytest.fixture(scope="module")
def mesh():
    return generate_fillet(3)


def _same_model(a, b) -> bool:
    return a.name == b.name and all(np.array_equal(getattr(a, field), getattr(b, field))
                                    for field in ("edges", "box_centers", "box_half_extents", "masses"))


def test_a_chain_model_built_once_is_read_back_bit_for_bit(cache, mesh, monkeypatch):
    built = line_world.chain_model(mesh, 40)
    assert len(list((cache / "models").glob("*.pickle"))) == 1
    assert not _same_model(line_world.chain_model(mesh, 20), built)  # another segment count, another entry
    monkeypatch.setattr(line_world, "build_fillet_model", lambda *a: pytest.fail("rebuilt a cached model"))
    again = line_world.chain_model(mesh, 40)
    assert _same_model(again, built) and _same_model(again, build_fillet_model(mesh, 40, NOMINAL_MASS))


def test_a_turned_copy_is_built_not_cached(cache, mesh):
    from woody_sim.meshes import yawed

    turned = yawed(mesh, 12.0)
    assert _same_model(line_world.chain_model(turned, 40), build_fillet_model(turned, 40, NOMINAL_MASS))
    assert not (cache / "models").exists()


def test_a_mesh_file_is_read_once_until_it_changes(cache, tmp_path):
    source = tmp_path / "fillet.obj"
    source.write_bytes((BUILTIN_DIR / "seed0001.obj").read_bytes())
    first = load_mesh(source)
    second = load_mesh(source)
    assert second is not first and np.array_equal(second.mesh.vertices, first.mesh.vertices)
    assert len(list((cache / "meshes").glob("*.pickle"))) == 1
    source.write_bytes((BUILTIN_DIR / "seed0002.obj").read_bytes())
    changed = load_mesh(source)
    assert changed.mesh.vertices.shape != first.mesh.vertices.shape
    assert len(list((cache / "meshes").glob("*.pickle"))) == 2


def test_a_result_that_warned_is_not_stored_so_every_run_warns(cache):
    def compute():
        warnings.warn("converted from millimetres", UserWarning, stacklevel=2)
        return 42

    for _ in range(2):
        with pytest.warns(UserWarning, match="millimetres"):
            assert disk_cache.cached("things", "key", compute, int) == 42
    assert not (cache / "things").exists()


def test_a_corrupt_entry_is_recomputed_and_replaced(cache):
    (cache / "things").mkdir()
    entry = cache / "things" / "key.pickle"
    entry.write_bytes(b"not a pickle")
    assert disk_cache.cached("things", "key", lambda: 7, int) == 7
    assert disk_cache.cached("things", "key", lambda: pytest.fail("recomputed"), int) == 7


def test_an_unwritable_cache_only_costs_the_computation(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("a file where the cache folder would be")
    monkeypatch.setenv(disk_cache.ENV_VAR, str(blocker))
    assert disk_cache.cached("things", "key", lambda: 7, int) == 7

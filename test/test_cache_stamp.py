"""The numba cache of a kernel follows every kernel source it may call (gyro_sim/compiled/cache_stamp.py)."""
import shutil

from gyro_sim.compiled import cache_stamp


def _locator(dispatcher):
    return dispatcher._cache._impl.locator


def test_the_tick_loops_cache_follows_the_frozen_flow_step(tmp_path):
    """Found in issue 28's work: the compiled tick loop (engine/ticks.py) calls the frozen-flow step
    (compiled/frozen_flow.py), but numba kept its cache under the stamp of ticks.py alone; after an edit of the step
    only, the tick loop ran the old step from its cache and test_ticks' runs (tick loop against the Python loop)
    differed in every array. Its cache, and every stamped kernel's, is now kept under one stamp of all the kernel
    sources, which an edit of frozen_flow.py changes."""
    from gyro_sim.compiled import frozen_flow, kernels
    from gyro_sim.engine import ticks

    for kernel in (ticks.breaks, frozen_flow.integrate_frozen, kernels.integrate):
        loc = _locator(kernel)
        assert getattr(type(loc), "_gyro_sim", False), type(loc)
        assert loc.get_source_stamp() == cache_stamp.stamp()
    # a copy of the sources: an edit of the frozen-flow step alone changes the stamp
    root = tmp_path / "src"
    for f in cache_stamp.kernel_sources():
        rel = next(f.relative_to(p) for p in f.parents if (p / "gyro_sim").is_dir())
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(f, root / rel)
    before = cache_stamp.stamp(root)
    assert before == cache_stamp.stamp()
    ff = root / "gyro_sim" / "compiled" / "frozen_flow.py"
    ff.write_text(ff.read_text() + "\n# an edit\n")
    assert cache_stamp.stamp(root) != before


def test_the_control_laws_keep_numbas_own_stamp():
    """gyro_ctl's law kernels may be imported before the stamping locators are installed; so that every process
    keeps them under the same stamp (not ours in one and numba's in the next, each compiling over the other's),
    they always keep numba's (their own file's: they call no other module's kernels)."""
    from numba.core.registry import CPUDispatcher

    from gyro_ctl import law_kernels

    kernels = [k for k in vars(law_kernels).values()
               if isinstance(k, CPUDispatcher) and getattr(k._cache, "_impl", None) is not None]
    assert kernels
    for k in kernels:
        assert not getattr(type(_locator(k)), "_gyro_sim", False)

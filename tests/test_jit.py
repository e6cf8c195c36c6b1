"""The numba compilation of the per-step kernels (l1b2.physics.jit)."""

from __future__ import annotations

import pytest
from l1b2.physics import coupled as cp
from l1b2.physics.jit import jit_status


def test_every_kernel_compiles_where_numba_is_installed(monkeypatch):
    # numba is a dependency: a kernel that fails to compile falls back to Python silently (and the tests of
    # the compiled kernels skip), so a failure to compile is a failure here
    pytest.importorskip("numba")
    monkeypatch.delenv("L1B2_JIT", raising=False)
    from l1b2.physics import interface, slider, stator
    for name, get in (("interface", interface.compiled_kernel), ("stator", stator.compiled_envelope_step),
                      ("slider", slider.compiled_step), ("coupled", cp.compiled_substeps)):
        assert get() is not None, (name, jit_status())


def test_a_family_across_modules_compiles_and_its_cache_key_follows_every_file(tmp_path, monkeypatch):
    # the fused step's family spans four modules; numba checks only the entry's file, so the cache key is
    # the digest of every file of the family: it changes when a helper's module changes
    from l1b2.physics import jit
    (tmp_path / "l1b2_fam_a.py").write_text("from l1b2_fam_b import helper\n\n\ndef entry(x):\n"
                                            "    return helper(x) + 1.0\n")
    (tmp_path / "l1b2_fam_b.py").write_text("def helper(x):\n    return 2.0 * x\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("L1B2_CACHE_DIR", str(tmp_path / "cache"))
    import l1b2_fam_a
    import l1b2_fam_b
    family = {"helper": l1b2_fam_b.helper, "entry": l1b2_fam_a.entry}
    digest = jit.family_digest(family)
    compiled = jit.compile_family(family, "entry", "float64(float64)")
    assert compiled is not None and compiled(2.0) == 5.0
    assert l1b2_fam_a.entry(2.0) == 5.0  # the module's own function stays plain Python
    assert [p.name for p in (tmp_path / "cache" / "numba").iterdir()] == [f"l1b2_fam_a-{digest}"]
    (tmp_path / "l1b2_fam_b.py").write_text("def helper(x):\n    return 3.0 * x\n")
    assert jit.family_digest(family) != digest
    assert jit.family_digest({"entry": l1b2_fam_a.entry}) != digest


def test_fused_step_checks_the_ranges_the_blocks_declare():
    # the compiled step hands a step to the blocks when an internal signal leaves the range a block accepts;
    # its limits are the blocks' Var declarations
    from l1b2.cosim.blocks import InterfaceBlock, SliderBlock, StatorBlock
    decl = {(cls.__name__, v.name): (v.min, v.max) for cls in (StatorBlock, InterfaceBlock, SliderBlock)
            for v in cls.INPUTS}
    assert decl["StatorBlock", "s"] == cp.LIM_S
    assert decl["InterfaceBlock", "U_l"] == decl["InterfaceBlock", "U_w"] == cp.LIM_U
    assert decl["InterfaceBlock", "delta"] == cp.LIM_DELTA
    assert decl["InterfaceBlock", "v"] == cp.LIM_V
    assert decl["InterfaceBlock", "F_p"] == decl["SliderBlock", "F_p"] == cp.LIM_FP
    assert decl["SliderBlock", "F_d"] == cp.LIM_FD
    assert all(decl["StatorBlock", f] == (None, None) for f in ("F_N1_sin", "F_N1_cos", "F_T1_sin", "F_T1_cos"))

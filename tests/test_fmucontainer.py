"""A standard SSP tool drives the motor: fmu-manipulation-toolbox's ``fmucontainer`` builds one FMU from
``L1B2Motor.ssp`` (its system connectors become the container's inputs and outputs) and fmpy runs it.

Skipped when fmu-manipulation-toolbox is not installed (it is in the test extras).
"""

from __future__ import annotations

import shutil
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("fmu_manipulation_toolbox")

H = 2e-4
SYSTEM_INPUTS = ["V_s", "duty", "f_s", "T", "direction", "m_load"]
SYSTEM_OUTPUTS = ["v", "s", "V0", "U_l", "U_w", "F_d"]
RUN = r"""
import sys
from fmu_manipulation_toolbox.cli.fmucontainer import fmucontainer
sys.argv = ["fmucontainer"] + sys.argv[1:]
fmucontainer()
"""


def worker_container(fmu_path, cases):
    """fmpy runs the container FMU; each case: (inputs held, or a switch time for direction, stop time)."""
    import fmpy
    out = {}
    for name, (inputs, switch_s, stop_s) in cases.items():
        signal = None
        if switch_s is not None:  # direction +1 until switch_s, then -1: an input that changes during the run
            signal = np.array([(0.0, 1.0), (switch_s - 1e-9, 1.0), (switch_s, -1.0), (stop_s, -1.0)],
                              dtype=[("time", float), ("direction", float)])
        r = fmpy.simulate_fmu(fmu_path, stop_time=stop_s, output_interval=H, start_values=inputs, input=signal,
                              output=["v", "s", "V0"])
        out[name] = {k: r[k].tolist() for k in ("time", "v", "s", "V0")}
    return out


def worker_ours(ssp_path, cases):
    """Our master on the same archive, same inputs (constant-input cases only)."""
    from l1b2.cosim.master import CoSimulation
    out = {}
    with CoSimulation(ssp_path, step_s=H, keep_instances=True) as cs:
        for name, (inputs, switch_s, stop_s) in cases.items():
            r = cs.run(stop_s, inputs, start_values={"Slider.s0": 0.0, "Stator.s": 0.0},  # the FMUs' default s0
                       record=["Slider.v", "Slider.s"])
            out[name] = {"v": r["Slider.v"].tolist(), "s": r["Slider.s"].tolist()}
    return out


def _mid_speed(res) -> float:
    """Mean speed between 5 and 15 mm: the runs start at the centre (the Slider FMU's default s0; the container
    does not expose the subsystems' parameters), so this is the steady part of the way to the far end stop."""
    s, v = np.asarray(res["s"]), np.asarray(res["v"])
    mid = (s > 0.005) & (s < 0.015)
    return float(np.mean(v[mid]))


@pytest.fixture(scope="module")
def container(exported, tmp_path_factory):
    out, _ = exported
    work = tmp_path_factory.mktemp("fmucontainer")
    shutil.copy(out / "L1B2Motor.ssp", work / "motor.ssp")
    proc = subprocess.run([sys.executable, "-c", RUN, "-container", f"motor.ssp:{H}", "-fmu-directory", ".",
                           "-no-auto-input", "-no-auto-output"], cwd=work, capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0 and (work / "motor.fmu").is_file(), proc.stdout[-3000:] + proc.stderr[-3000:]
    return work / "motor.fmu", proc.stdout + proc.stderr


def test_container_exposes_the_system_connectors(container):
    # reference: SSP 1.0 - connections to system connectors in ssd:Connections; the container's inputs and
    # outputs are exactly the system's, none of the subsystems' inputs is left unconnected
    import fmpy
    fmu, log = container
    md = fmpy.read_model_description(str(fmu))
    assert [v.name for v in md.modelVariables if v.causality == "input"] == SYSTEM_INPUTS
    assert [v.name for v in md.modelVariables if v.causality == "output"] == SYSTEM_OUTPUTS
    assert "is not connected" not in "\n".join(l for l in log.splitlines() if "Input" in l)


def test_container_is_driven_through_v_s_load_and_direction(container, exported, isolated, motor):
    # reference: our master on the same L1B2Motor.ssp (Gauss-Seidel; the container steps its FMUs on the
    # previous values, so only the transient differs: compare the mean speed between 5 and 15 mm), and the
    # physics' own ordering: a lower supply or an opposing load is slower, direction -1 drives toward -position
    from l1b2.physics import driver as drv
    fmu, _ = container
    V_s = float(drv.supply_for_voltage_V(motor.driver, 324.0, 1.0, 48500.0, 25.0))
    base = {"V_s": V_s, "duty": 1.0, "f_s": 48500.0, "T": 25.0, "direction": 1.0, "m_load": 0.0}
    cases = {"324V": (base, None, 0.15), "324V_0.05kg": (dict(base, m_load=0.05), None, 0.2),
             "220V": (dict(base, V_s=V_s * 220.0 / 324.0), None, 0.25)}
    got = isolated(__file__, "worker_container", str(fmu), {**cases, "reverse": (base, 0.05, 0.15)}).value
    ours = isolated(__file__, "worker_ours", str(exported[0] / "L1B2Motor.ssp"), cases).value
    for name in cases:
        assert _mid_speed(got[name]) == pytest.approx(_mid_speed(ours[name]), rel=2e-3), name
        assert got[name]["s"][-1] == pytest.approx(0.021, abs=1e-6), name  # reached the far end stop
    assert got["324V"]["V0"][-1] == pytest.approx(324.0, rel=1e-3)        # V_s reached the stator as V0
    assert _mid_speed(got["324V_0.05kg"]) < 0.95 * _mid_speed(got["324V"])
    assert _mid_speed(got["220V"]) < 0.8 * _mid_speed(got["324V"])
    rev = got["reverse"]
    t, v, s = (np.asarray(rev[k]) for k in ("time", "v", "s"))
    assert v[(t > 0.02) & (t < 0.05)].min() > 0.1                           # +1: toward +position
    assert v[t > 0.08].max() < -0.1 and s[-1] < s[np.searchsorted(t, 0.05)]  # -1: back toward -position

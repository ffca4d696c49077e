"""The kernel's skeleton: KERNEL_TEMPLATE and the per-IMU templates, with `$name` slots that
imu_emulator.codegen.generate fills (`fill`). Their comments are the generated source's too: they say why a line
is there where the line cannot (imu_emulator.codegen.explain writes the header, glossary and notes)."""
from __future__ import annotations

CHUNK = 256      # samples per chunk: the periodic phases of a chunk are computed before its samples (below)

# The skeleton. $name lines are slots, replaced by lines indented like the slot. Samples go in chunks: first
# every periodic phase of the chunk (short independent chains the CPU overlaps across samples: 50 -> 35
# ns/sample on the circle scene; stored phases[i, jj], one contiguous row per phase, so that this loop
# vectorizes: 40 -> 27 ns/sample of the kinematics alone, tools/bench_against.py), then the per-sample body.
# k = scene sample (motion), s = run sample (noise). Why kernel_body and kernel: the comment inside.
KERNEL_TEMPLATE = '''\
$header
import math
import numba
import numpy as np
$imports
EPS_V2 = $eps_v2
CHUNK = $chunk
N_PHASE = $n_phase
$constants
$imu_functions

@numba.njit(cache=True, nogil=True, error_model='numpy')
def kernel_body($args, phases):
    # kernel_body allocates nothing (its scratch `phases` is an argument), so its machine code runs without
    # numba's runtime (imu_emulator.native.objects); `kernel` below allocates the scratch and calls it.
    # tangent attitude's last defined heading and pitch (cos, sin), carried across blocks
    hcy, hsy, hcp, hsp = hold[0], hold[1], hold[2], hold[3]
    # the scene's numbers, run-time parameters (imu_emulator.codegen.plan): read once per call into locals
    $load_params
    $load_state
    # samples in chunks of CHUNK: every periodic phase of the chunk first, then the per-sample body
    for c0 in range(0, n, CHUNK):
        mc = min(CHUNK, n - c0)
        $phase_stage
        for jj in range(mc):
            j = c0 + jj
            k = k0 + j
            s = s0 + j
            $clock
            $increments
            # t from the integer sample index, never accumulated
            t = $t0 + k * $dt$clock_shift
            $motion
            # -- stage 1: navigation frame
            fnx = ax
            fny = ay
            fnz = az
            $navigation
            # specific force at S in body axes: R^T (a - g)
            fbx = r00 * fnx + r10 * fny + r20 * fnz
            fby = r01 * fnx + r11 * fny + r21 * fnz
            fbz = r02 * fnx + r12 * fny + r22 * fnz
            $attitude
            $per_imu
            $truth
    $store_state
    hold[0], hold[1], hold[2], hold[3] = hcy, hsy, hcp, hsp


@numba.njit(cache=True, nogil=True, error_model='numpy')
def kernel($args):
    kernel_body($args, np.empty((N_PHASE, CHUNK)))
'''

# Stages 2 and 3 up to the sensor axes: the sample's, and the increments' at each quadrature node.
IMU_FRAME_TEMPLATE = '''\
# -- IMU $m, stage 2: body frame at the IMU
fax = fbx
fay = fby
faz = fbz
gwx = $gwx
gwy = $gwy
gwz = $gwz
$body
$increment
# -- stage 3: sensor frame
ox = fax
oy = fay
oz = faz
gx = gwx
gy = gwy
gz = gwz
$frame
'''

PER_IMU_TEMPLATE = IMU_FRAME_TEMPLATE + '''\
$sensor
# -- stage 4: sensor output
$output
out_acc[$m, j, 0] = ox
out_acc[$m, j, 1] = oy
out_acc[$m, j, 2] = oz
out_gyro[$m, j, 0] = gx
out_gyro[$m, j, 1] = gy
out_gyro[$m, j, 2] = gz
$quat
$bias_truth
'''


def fill(template: str, **slots) -> str:
    """Replace each `$name` in the template; a slot alone on its line takes a list of lines, indented like it."""
    out = []
    for line in template.splitlines():
        stripped = line.strip()
        if stripped.startswith("$") and stripped[1:] in slots and isinstance(slots[stripped[1:]], list):
            indent = line[: len(line) - len(line.lstrip())]
            out += [indent + x for x in slots[stripped[1:]]]
            continue
        for name, value in slots.items():
            if not isinstance(value, list):
                line = line.replace(f"${name}", str(value))
        out.append(line)
    return "\n".join(out) + "\n"


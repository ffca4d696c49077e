"""Writes loop_track.csv: the spec's small loop with a third harmonic in z, and a yaw oscillation.

200 Hz for 5 s (1001 rows, both ends included), f = 1 Hz:
x = 0.8 cos 2πt, y = 0.8 sin 2πt, z = 0.3 cos 6πt, roll = pitch = 0, yaw = 0.3 cos 2πt.
Twelve decimals: rounding then adds about 1e-12/h^3 ~ 1e-5 m/s^3 of noise to the jerk, far below any method's
truncation error at this rate.
"""
from pathlib import Path

import numpy as np

t = np.arange(1001) * 0.005
w = 2 * np.pi
columns = [t, 0.8 * np.cos(w * t), 0.8 * np.sin(w * t), 0.3 * np.cos(3 * w * t),
           np.zeros_like(t), np.zeros_like(t), 0.3 * np.cos(w * t)]
np.savetxt(Path(__file__).with_name("loop_track.csv"), np.column_stack(columns), delimiter=",",
           fmt=["%.3f"] + ["%.12f"] * 6, header="t,x,y,z,roll,pitch,yaw", comments="")

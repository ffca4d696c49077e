"""The waypoints of examples/sitl_flight.toml: 40 s at rest on the ground, climb, hover, three figure eights eased
in and out, hover, landing, rest, sampled densely from smooth curves so that the quintic spline the `waypoints`
shape puts through them follows the curves. (The scene's first version had 81 sparse waypoints: its spline rang,
so the "40 s on the ground" rose 2.9 m and moved at up to 0.7 m/s, and PX4's EKF2 dropped the GNSS as drifting.)
The attitude at each waypoint is a multicopter's: body z against the specific force the curve needs (thrust along
it), nose along the horizontal velocity (held while hovering).

    .venv/bin/python tools/interop/sitl_flight_waypoints.py    # prints the three TOML lines to paste
"""
import numpy as np
from scipy.spatial.transform import Rotation as R

G = 9.80665      # standard gravity; the attitude only needs its direction, the tilt barely its size
def smooth7(u):   # 0..1 with zero velocity, acceleration and jerk at both ends
    u = np.clip(u, 0, 1)
    return 35*u**4 - 84*u**5 + 70*u**6 - 20*u**7

T0, T1 = 60.0, 270.0          # figure eights
RAMP = 10.0                   # s of easing in and out of the eights' phase speed
W = 6*np.pi / (T1 - T0 - RAMP)  # three loops: total phase 6 pi
def phase(t):
    # phase speed W * s(t), s ramps 0->1 over RAMP after T0 and 1->0 over RAMP before T1 (smooth7 ramps)
    tt = np.linspace(T0, t, 4001) if t > T0 else np.array([T0, T0])
    s = smooth7((tt - T0)/RAMP) * smooth7((T1 - tt)/RAMP)
    return W * np.trapezoid(s, tt)

def position(t):
    if t <= 40: return np.array([0., 0, 0])
    if t <= 52: return np.array([0., 0, -10*smooth7((t-40)/12)])
    if t <= T0: return np.array([0., 0, -10])
    if t <= T1:
        p = phase(t); return np.array([30*np.sin(p), 15*np.sin(2*p), -10])
    if t <= 274: return np.array([0., 0, -10])
    if t <= 290: return np.array([0., 0, -10*(1-smooth7((t-274)/16))])
    return np.array([0., 0, 0])

def waypoints():
    """(times s, NED positions m, [roll, pitch, yaw] deg, NED velocities m/s) of the scene's waypoints."""
    times = np.concatenate([np.arange(0, 40, 2.0), np.arange(40, 52, 0.5), np.arange(52, 60, 1.0),
                            np.arange(60, 270, 0.5), np.arange(270, 274, 1.0), np.arange(274, 290, 0.5),
                            np.arange(290, 300.001, 2.0)])
    P = np.array([position(t) for t in times])
    # derivatives by finite differences of the exact curve
    h = 1e-3
    V = np.array([(position(t+h) - position(t-h))/(2*h) if 0 < t < 300 else np.zeros(3) for t in times])
    A = np.array([(position(t+h) - 2*position(t) + position(t-h))/h**2 if 0 < t < 300 else np.zeros(3) for t in times])
    yaw = []
    last = np.radians(45.0)
    for v in V:
        if np.hypot(v[0], v[1]) > 0.05:
            heading = np.arctan2(v[1], v[0])
            last += (heading - last + np.pi) % (2*np.pi) - np.pi      # unwrapped: the attitude spline turns the short way
        yaw.append(last)
    att = []
    for a, y in zip(A, yaw):
        f = a - np.array([0, 0, G])
        zb = -f/np.linalg.norm(f)
        heading = np.array([np.cos(y), np.sin(y), 0])
        xb = heading - zb*np.dot(heading, zb); xb /= np.linalg.norm(xb)
        yb = np.cross(zb, xb)
        rot = R.from_matrix(np.column_stack([xb, yb, zb]))
        _, pitch, roll = rot.as_euler("ZYX", degrees=True)
        att.append([roll, pitch, np.degrees(y)])
    return times, P, np.array(att), V


def _fmt(rows, decimals: int) -> str:
    rows = np.round(rows, decimals) + 0.0       # + 0.0: no "-0"
    return "[" + ", ".join("[" + ", ".join(f"{v:.{decimals}f}".rstrip("0").rstrip(".") for v in r) + "]"
                           for r in rows) + "]"


def main():
    times, P, att, V = waypoints()
    print("positions_m =", _fmt(P, 4))
    print("times_s = [" + ", ".join(f"{t:g}" for t in times) + "]")
    print("attitudes_deg =", _fmt(att, 3))
    print(f"# {len(times)} waypoints; max speed {np.linalg.norm(V, axis=1).max():.2f} m/s; max tilt "
          f"{max(np.hypot(r[0], r[1]) for r in att):.2f} deg; W {W:.5f} rad/s", flush=True)


if __name__ == "__main__":
    main()

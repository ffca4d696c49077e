"""IMU emulator: a described motion becomes what a real IMU would put on the wire.

Python API:
    scene = load_scene("examples/helix.toml")      # or scene_from_dict({...})
    samples = simulate(scene)                      # SampleBlock: t_s, accel, gyro (n_imu, n, 3), quat
    sim = Simulation(scene); sim.block(k0, n)      # block-wise, for long or live runs
"""
from imu_emulator.errors import DataError, ImuEmulatorError, SceneError, TargetError
from imu_emulator.samples import SampleBlock
from imu_emulator.scene import Scene, load_scene
from imu_emulator.scene import from_dict as scene_from_dict


def __getattr__(name):
    # Simulation pulls in numba; importing the package for scene validation alone should not.
    if name in ("Simulation", "simulate"):
        import importlib
        return getattr(importlib.import_module("imu_emulator.simulation"), name)
    raise AttributeError(name)


__all__ = ["DataError", "ImuEmulatorError", "SampleBlock", "Scene", "SceneError", "Simulation", "TargetError",
           "load_scene", "scene_from_dict", "simulate"]

"""pybullet's DeepMimic humanoid tracking a mocap clip: simulated seconds per
wall second on one thread, for `benches/physics_vs_pybullet.sh`.

The humanoid, the stable PD controller (C++ path), the solver iterations and
the ground are those of pybullet_envs.deep_mimic (PyBulletDeepMimicEnv with
HumanoidStablePD); the PD target is the reference pose of the clip at the
current time (action 0 in our environment's terms). Only the PD application
and the physics step are timed; the clip is restarted when the character
falls or the clip ends. Needs `pip install pybullet` (PyPI).
"""

import argparse
import importlib.util
import json
import math
import sys
import time
import types

import pybullet
import pybullet_data
from pybullet_utils import bullet_client

# pybullet_envs/__init__.py registers gym environments with an old gym API;
# the DeepMimic modules themselves need none of it, so the package is
# entered without running its __init__.
_spec = importlib.util.find_spec("pybullet_envs")
_pkg = types.ModuleType("pybullet_envs")
_pkg.__path__ = list(_spec.submodule_search_locations)
sys.modules["pybullet_envs"] = _pkg
from pybullet_envs.deep_mimic.env import humanoid_stable_pd, motion_capture_data  # noqa: E402

MAX_FORCES = [
    0, 0, 0, 0, 0, 0, 0, 200, 200, 200, 200, 50, 50, 50, 50, 200, 200, 200, 200, 150, 90,
    90, 90, 90, 100, 100, 100, 100, 60, 200, 200, 200, 200, 150, 90, 90, 90, 90, 100, 100,
    100, 100, 60
]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--dt", type=float, default=1.0 / 1200.0)
    ap.add_argument("--seconds", type=float, default=2.0, help="wall seconds of stepping to time")
    ap.add_argument("--motion", default="data/motions/humanoid3d_walk.txt")
    args = ap.parse_args()

    client = bullet_client.BulletClient(connection_mode=pybullet.DIRECT)
    client.setAdditionalSearchPath(pybullet_data.getDataPath())
    z2y = client.getQuaternionFromEuler([-math.pi * 0.5, 0, 0])
    plane = client.loadURDF("plane_implicit.urdf", [0, 0, 0], z2y, useMaximalCoordinates=True)
    client.configureDebugVisualizer(client.COV_ENABLE_Y_AXIS_UP, 1)
    client.setGravity(0, -9.8, 0)
    client.setPhysicsEngineParameter(numSolverIterations=10)
    client.changeDynamics(plane, linkIndex=-1, lateralFriction=0.9)
    mocap = motion_capture_data.MotionCaptureData()
    mocap.Load(pybullet_data.getDataPath() + "/" + args.motion)
    humanoid = humanoid_stable_pd.HumanoidStablePD(client, mocap, args.dt, False, None)
    client.setTimeStep(args.dt)
    client.setPhysicsEngineParameter(numSubSteps=1)

    def restart():
        humanoid.setSimTime(0.0)
        humanoid.resetPose()
        return 0.0

    t = restart()
    wall = 0.0
    steps = 0
    restarts = 0
    cycle = humanoid.getCycleTime()
    while wall < args.seconds:
        humanoid.setSimTime(t)
        pose = humanoid.computePose(humanoid._frameFraction)
        start = time.perf_counter()
        humanoid.computeAndApplyPDForces(pose, maxForces=MAX_FORCES)
        client.stepSimulation()
        wall += time.perf_counter() - start
        steps += 1
        t += args.dt
        if t >= cycle or humanoid.terminates():
            t = restart()
            restarts += 1
    print(json.dumps({
        "engine": "pybullet " + str(pybullet.getAPIVersion()),
        "dt": args.dt,
        "physics_steps": steps,
        "sim_seconds_per_wall_second": steps * args.dt / wall,
        "restarts": restarts,
    }))


if __name__ == "__main__":
    main()

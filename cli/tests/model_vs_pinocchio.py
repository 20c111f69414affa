#!/usr/bin/env python3
"""Checks the JSON of `softcontact model` against Pinocchio on the same URDF, state and frame.

Usage: model_vs_pinocchio.py URDF MODEL.json   (exit 0 when every term agrees to 1e-9 relative)
"""
import json
import sys

import numpy as np
import pinocchio as pin


def close(name, ours, ref):
    ours, ref = np.asarray(ours, dtype=float), np.asarray(ref, dtype=float)
    scale = max(1.0, float(np.max(np.abs(ref))))
    err = float(np.max(np.abs(ours - ref)))
    if err > 1e-9 * scale:
        sys.exit(f"{name}: max difference {err:g}\nours {ours}\npin  {ref}")


urdf, path = sys.argv[1], sys.argv[2]
out = json.load(open(path))
model = pin.buildModelFromUrdf(urdf)
data = model.createData()
q, dq, ddq = (np.array(out[k]) for k in ("q", "dq", "ddq"))

names = [model.names[i] for i in range(1, model.njoints)]
if [j["name"] for j in out["joints"]] != names:
    sys.exit(f"joint names {out['joints']} vs {names}")
close("lower limits", [j["lower"] for j in out["joints"]], model.lowerPositionLimit)
close("upper limits", [j["upper"] for j in out["joints"]], model.upperPositionLimit)
close("velocity limits", [j["velocity"] for j in out["joints"]], model.velocityLimit)
close("effort limits", [j["effort"] for j in out["joints"]], model.effortLimit)

pin.framesForwardKinematics(model, data, q)
for name, f in out["frames"].items():
    fid = model.getFrameId(name)
    close(name + " translation", f["translation"], data.oMf[fid].translation)
    close(name + " rotation", f["rotation"], data.oMf[fid].rotation)
fid = model.getFrameId(out["jacobian_frame"])
pin.computeJointJacobians(model, data, q)
close("jacobian", out["jacobian"], pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED))
m = pin.crba(model, data, q)
close("mass_matrix", out["mass_matrix"], np.triu(m) + np.triu(m, 1).T)
close("gravity", out["gravity"], pin.computeGeneralizedGravity(model, data, q))
close("rnea", out["rnea"], pin.rnea(model, data, q, dq, ddq))
print(f"softcontact model agrees with Pinocchio {pin.__version__} on {len(out['frames'])} frames")

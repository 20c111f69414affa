#!/usr/bin/env python3
"""Reference values from Pinocchio for the planar floating-base chain (run by tests/planar_pinocchio.rs).

Builds the chain from the JSON description on stdin — links with length, mass, com along the link and
inertia about the plane's normal, and gravity along -y — as Pinocchio joints PX, PY, RZ (the floating
base) and one RZ per further link, then writes, for each given state (q, dq), M, nle and the world
position and linear Jacobian (LOCAL_WORLD_ALIGNED) of every node.

Usage: planar_pinocchio.py < IN.json > OUT.json
"""
import json
import sys

import numpy as np
import pinocchio as pin


def main():
    spec = json.load(sys.stdin)
    model = pin.Model()
    model.gravity.linear = np.array([0.0, -spec["gravity"], 0.0])
    parent = 0
    parent = model.addJoint(parent, pin.JointModelPX(), pin.SE3.Identity(), "x")
    parent = model.addJoint(parent, pin.JointModelPY(), pin.SE3.Identity(), "y")
    placement = pin.SE3.Identity()
    frames = []
    for k, link in enumerate(spec["links"]):
        parent = model.addJoint(parent, pin.JointModelRZ(), placement, f"q{k}")
        # Rotations about x and y never happen; any positive moments there leave the planar motion alone.
        inertia = np.diag([1e-3, 1e-3, link["inertia"]])
        model.appendBodyToJoint(parent, pin.Inertia(link["mass"], np.array([link["com"], 0.0, 0.0]), inertia), pin.SE3.Identity())
        placement = pin.SE3(np.eye(3), np.array([link["length"], 0.0, 0.0]))
        if k == 0:
            frames.append(model.addFrame(pin.Frame("node0", parent, pin.SE3.Identity(), pin.FrameType.OP_FRAME)))
        frames.append(model.addFrame(pin.Frame(f"node{k + 1}", parent, placement, pin.FrameType.OP_FRAME)))
    data = model.createData()
    out = []
    for s in spec["states"]:
        q, dq = np.array(s["q"]), np.array(s["dq"])
        pin.computeAllTerms(model, data, q, dq)
        pin.updateFramePlacements(model, data)
        nodes, jacobians = [], []
        for f in frames:
            nodes.append(data.oMf[f].translation[:2].tolist())
            j = pin.getFrameJacobian(model, data, f, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
            jacobians.append(j[:2].tolist())
        out.append({
            "mass_matrix": pin.crba(model, data, q).tolist(),
            "nonlinear_effects": pin.nonLinearEffects(model, data, q, dq).tolist(),
            "nodes": nodes,
            "jacobians": jacobians,
        })
    json.dump({"pinocchio": pin.__version__, "states": out}, sys.stdout)


if __name__ == "__main__":
    main()

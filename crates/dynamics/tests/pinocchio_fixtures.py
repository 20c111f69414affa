#!/usr/bin/env python3
"""Reference values from Pinocchio for the dynamics tests (run by tests/pinocchio.rs on every test run).

For random states (q within the joint limits, dq, ddq, tau, and an external wrench at `lwr_tool`) writes
JSON with, per state: the world placement of every URDF link frame, frame Jacobians in world-aligned and
local axes, RNEA with and without the external wrench, CRBA, g, h, ABA, J̇q̇ of the tool frame, and the
kinetic and potential energies.

Usage: pinocchio_fixtures.py URDF OUT.json [--states N] [--seed S]
"""
import argparse
import json

import numpy as np
import pinocchio as pin

TOOL = "lwr_tool"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("urdf")
    ap.add_argument("out")
    ap.add_argument("--states", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()

    model = pin.buildModelFromUrdf(args.urdf)
    data = model.createData()
    rng = np.random.default_rng(args.seed)
    links = [f for f in model.frames if f.type == pin.FrameType.BODY]
    tool = model.getFrameId(TOOL)
    tool_joint = model.frames[tool].parentJoint

    states = []
    for _ in range(args.states):
        q = rng.uniform(model.lowerPositionLimit, model.upperPositionLimit)
        dq = rng.uniform(-2.0, 2.0, model.nv)
        ddq = rng.uniform(-5.0, 5.0, model.nv)
        tau = rng.uniform(-30.0, 30.0, model.nv)
        force = rng.uniform(-50.0, 50.0, 3)
        torque = rng.uniform(-5.0, 5.0, 3)

        pin.forwardKinematics(model, data, q, dq, 0 * dq)
        pin.updateFramePlacements(model, data)
        pin.computeJointJacobians(model, data, q)
        frames, jac_world, jac_local = {}, {}, {}
        for f in links:
            fid = model.getFrameId(f.name)
            m = data.oMf[fid]
            frames[f.name] = {"translation": m.translation.tolist(), "rotation": m.rotation.tolist()}
            jac_world[f.name] = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED).tolist()
            jac_local[f.name] = pin.getFrameJacobian(model, data, fid, pin.LOCAL).tolist()
        bias = pin.getFrameClassicalAcceleration(model, data, tool, pin.LOCAL_WORLD_ALIGNED)

        # The wrench acts on the robot at the tool origin, world axes; Pinocchio wants it per joint, in
        # the joint's local frame, about the joint origin.
        oMi = data.oMi[tool_joint]
        p_tool = data.oMf[tool].translation
        fext = [pin.Force.Zero() for _ in range(model.njoints)]
        fext[tool_joint] = pin.Force(
            oMi.rotation.T @ force, oMi.rotation.T @ (torque + np.cross(p_tool - oMi.translation, force))
        )

        mass = pin.crba(model, data, q)
        mass = np.triu(mass) + np.triu(mass, 1).T
        states.append(
            {
                "q": q.tolist(),
                "dq": dq.tolist(),
                "ddq": ddq.tolist(),
                "tau": tau.tolist(),
                "force": force.tolist(),
                "torque": torque.tolist(),
                "frames": frames,
                "jacobian_world": jac_world,
                "jacobian_local": jac_local,
                "tool_bias_acceleration": np.concatenate([bias.linear, bias.angular]).tolist(),
                "rnea": pin.rnea(model, data, q, dq, ddq).tolist(),
                "rnea_external": pin.rnea(model, data, q, dq, ddq, fext).tolist(),
                "mass_matrix": mass.tolist(),
                "gravity": pin.computeGeneralizedGravity(model, data, q).tolist(),
                "nonlinear_effects": pin.nonLinearEffects(model, data, q, dq).tolist(),
                "aba": pin.aba(model, data, q, dq, tau).tolist(),
                "aba_external": pin.aba(model, data, q, dq, tau, fext).tolist(),
                "kinetic_energy": float(pin.computeKineticEnergy(model, data, q, dq)),
                "potential_energy": float(pin.computePotentialEnergy(model, data, q)),
            }
        )
    with open(args.out, "w") as fh:
        json.dump({"pinocchio": pin.__version__, "tool": TOOL, "states": states}, fh)


if __name__ == "__main__":
    main()

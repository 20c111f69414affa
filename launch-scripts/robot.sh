#!/usr/bin/env bash
# The four nodes against a real KRC (FRI) and Net F/T box (RDT): config/ parameter files with the
# config/robot.yaml overlay (edit its addresses first; add your own with --params-file). DDS uses the
# machine's network as ROS 2 does (set ROS_DOMAIN_ID). Same options as sim.sh except --surface.
exec "$(dirname "${BASH_SOURCE[0]}")/launch.sh" --robot "$@"

#!/usr/bin/env bash
# The simulated cell (sim_arm) and the four nodes: lwr_driver, ft_sensor, contact_estimator,
# deformation_controller, with the parameter files of config/. Options (see launch.sh --help):
#   --isolated        everything in a network namespace with only loopback (tests, the --graph demo)
#   --lockstep        faster than real time on /clock
#   --secure          ROS 2 security: authenticated, encrypted, each process held to its enclave's permissions
#   --surface KIND    sponge (default), dice, lab_sponge, lab_dice or none
#   --run CMD ARGS…   run CMD against the graph, then stop it (exit status: CMD's, or 1 if a node failed)
# Ctrl-C stops every node cleanly; if one node dies, the others are stopped.
exec "$(dirname "${BASH_SOURCE[0]}")/launch.sh" --sim "$@"

//! The product's nodes. Each node's logic is a plain struct driven by datagrams and messages
//! ([`lwr_driver::LwrDriver`], [`ft_sensor::FtSensorNode`]); [`runtime::udp`] and [`sim_arm`] are the socket
//! ends, kept thin, so the same logic runs against the real KRC and Net F/T box or the simulator.
// Safety checks are written `!(x <= limit)` on purpose: they are true for NaN, which must be refused.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod cell;
pub mod contact_estimator;
pub mod deformation_controller;
pub mod ft_sensor;
pub mod geometry;
pub mod identify;
pub mod lwr_driver;
pub mod messages;
pub mod runtime;
pub mod sim_arm;

//! The product's nodes. Each node's logic is a plain struct driven by datagrams and messages
//! ([`lwr_driver::LwrDriver`], [`ft_sensor::FtSensorNode`]); [`runtime::udp`] is the socket end, kept thin,
//! so the same logic runs against the real KRC and Net F/T box or the simulated cell (the package
//! `softcontact-simcell`, which this one does not depend on).
// Safety checks are written `!(x <= limit)` on purpose: they are true for NaN, which must be refused.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod contact_estimator;
pub mod deformation_controller;
pub mod ft_sensor;
pub mod geometry;
pub mod lwr_driver;
pub mod messages;
pub mod runtime;

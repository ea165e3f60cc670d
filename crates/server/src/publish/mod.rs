//! From solver to viewers: a scene made ready to serve ([`prepare`]), the solver thread that
//! solves it and applies edits ([`solver_thread`]), the conversion of solver values to wire
//! types ([`to_wire`], the only place the two meet), the solution cache ([`cache`]) and the
//! hub that holds the published version for every viewer ([`hub`]).

pub mod cache;
pub mod hub;
pub mod prepare;
pub mod solver_thread;
pub mod to_wire;

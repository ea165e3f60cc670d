//! A solution and its vocabulary: what a solve is asked for ([`request`]), what it reports
//! ([`report`]), the live solution that takes edits ([`session`]), the values viewers are sent at the mesh
//! vertices ([`vertices`]), and the offline path from a
//! scene file to a solved scene ([`pipeline`]).

mod bounce;
mod display;
mod gather_point;
pub(crate) mod locator;
pub mod pipeline;
pub mod report;
pub mod request;
pub mod session;
pub mod target;
pub mod vertices;

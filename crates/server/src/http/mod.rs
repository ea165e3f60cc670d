//! The HTTP and WebSocket face of one server: accepting connections under the caps
//! ([`listen`], [`admission`]), the routes ([`routes`]), one task per viewer ([`viewer`]), the
//! embedded browser page ([`page`]) and the Prometheus text ([`metrics`]).

pub mod admission;
pub mod listen;
pub mod metrics;
pub mod page;
pub mod routes;
pub mod viewer;

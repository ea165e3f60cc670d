//! One viewer's protocol state, with no I/O: every command (`view`, `watch`, `load`) feeds it
//! the server's binary messages and acts on what it says, so they all follow the protocol the
//! same way (docs/PROTOCOL.md, "Viewer state machine").

use wire::{ApplyError, ColourBuffer, FrameInfo, Hello, ServerMessage};

/// A viewer: the hello, the geometry version it belongs to, and the colours held.
#[derive(Debug, Default)]
pub struct Viewer {
    hello: Option<Hello>,
    geometry_version: u64,
    /// Patches every frame must have: the hello's, until a geometry change makes the next full
    /// frame say (a hierarchy's move changes its leaves).
    expected_vertices: Option<u32>,
    buffer: ColourBuffer,
}

/// What one message did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Step {
    /// The hello: the scene, its geometry version and vertex count.
    Hello(Hello),
    /// The geometry changed: fetch `/api/scene` again before rendering the next colours.
    GeometryChanged {
        /// The version to fetch.
        geometry_version: u64,
    },
    /// A frame was applied.
    Applied {
        /// Whether it was a full frame (else a delta).
        full: bool,
        /// Patches whose code changed.
        changed: usize,
        /// What the frame says of the state now held.
        info: FrameInfo,
    },
    /// A delta against a state this viewer does not hold: send
    /// [`wire::ClientMessage::RequestFull`] and wait.
    NeedsFull,
}

/// A server that broke the protocol.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProtocolError {
    /// The bytes are no message.
    #[error("bad message from the server: {0}")]
    Decode(#[from] wire::DecodeError),
    /// Anything before the hello.
    #[error("a message before the hello")]
    BeforeHello,
    /// A hello after the first.
    #[error("a second hello")]
    SecondHello,
    /// A frame whose vertex count is not the geometry's.
    #[error("a frame of {got} vertices for a geometry of {expected}")]
    PatchCount {
        /// Patches in the geometry.
        expected: u32,
        /// Patches in the frame.
        got: u32,
    },
}

impl Viewer {
    /// Decodes and applies one binary message from the server.
    pub fn receive(&mut self, bytes: &[u8]) -> Result<Step, ProtocolError> {
        let message = ServerMessage::decode(bytes)?;
        let (full, info, changed) = match (&message, self.hello) {
            (ServerMessage::Hello(hello), None) => {
                self.hello = Some(*hello);
                self.geometry_version = hello.geometry_version;
                self.expected_vertices = Some(hello.vertex_count);
                return Ok(Step::Hello(*hello));
            }
            (ServerMessage::Hello(_), Some(_)) => return Err(ProtocolError::SecondHello),
            (_, None) => return Err(ProtocolError::BeforeHello),
            (ServerMessage::GeometryChanged { geometry_version }, Some(_)) => {
                self.geometry_version = *geometry_version;
                self.expected_vertices = None;
                return Ok(Step::GeometryChanged {
                    geometry_version: *geometry_version,
                });
            }
            (ServerMessage::Full(frame), Some(_)) => {
                let changed = if self.buffer.colours.len() == frame.colours.len() {
                    wire::changes(&self.buffer.colours, &frame.colours).0.len()
                } else {
                    frame.colours.len()
                };
                (true, frame.info, changed)
            }
            (ServerMessage::Delta(frame), Some(_)) => (false, frame.info, frame.indices.len()),
        };
        let expected = self.expected_vertices.unwrap_or(info.vertex_count);
        if info.vertex_count != expected {
            return Err(ProtocolError::PatchCount {
                expected,
                got: info.vertex_count,
            });
        }
        match self.buffer.apply(&message) {
            Ok(()) => {}
            Err(ApplyError::BaseMismatch { .. }) => return Ok(Step::NeedsFull),
        }
        if full {
            self.expected_vertices = Some(info.vertex_count);
        }
        Ok(Step::Applied {
            full,
            changed,
            info,
        })
    }

    /// The server's hello, once received.
    pub fn hello(&self) -> Option<Hello> {
        self.hello
    }

    /// The geometry version the colours held belong to.
    pub fn geometry_version(&self) -> u64 {
        self.geometry_version
    }

    /// The colours held.
    pub fn buffer(&self) -> &ColourBuffer {
        &self.buffer
    }

    /// The colours held, taken out.
    pub fn into_buffer(self) -> ColourBuffer {
        self.buffer
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use wire::{DeltaFrame, FullFrame};

    fn hello(vertex_count: u32) -> Vec<u8> {
        ServerMessage::Hello(Hello {
            protocol_version: wire::PROTOCOL_VERSION,
            scene_id: 7,
            geometry_version: 1,
            vertex_count,
        })
        .encode()
    }

    fn info(version: u64, vertex_count: u32, is_final: bool) -> FrameInfo {
        FrameInfo {
            solution_version: version,
            sent_at_unix_micros: 0,
            scale: 1.0,
            vertex_count,
            is_final,
        }
    }

    fn full(version: u64, colours: Vec<u32>) -> Vec<u8> {
        ServerMessage::Full(FullFrame {
            info: info(version, colours.len() as u32, false),
            colours,
        })
        .encode()
    }

    fn delta(base: u64, version: u64, vertex_count: u32, changes: &[(u32, u32)]) -> Vec<u8> {
        ServerMessage::Delta(DeltaFrame {
            base_version: base,
            info: info(version, vertex_count, true),
            indices: changes.iter().map(|c| c.0).collect(),
            colours: changes.iter().map(|c| c.1).collect(),
        })
        .encode()
    }

    #[test]
    fn hello_then_full_then_delta_ends_with_the_servers_colours() {
        let mut viewer = Viewer::default();
        assert!(matches!(viewer.receive(&hello(3)), Ok(Step::Hello(_))));
        let step = viewer.receive(&full(1, vec![1, 2, 3])).unwrap();
        assert!(matches!(
            step,
            Step::Applied {
                full: true,
                changed: 3,
                ..
            }
        ));
        let step = viewer.receive(&delta(1, 2, 3, &[(2, 9)])).unwrap();
        assert!(matches!(
            step,
            Step::Applied {
                full: false,
                changed: 1,
                ..
            }
        ));
        assert_eq!(viewer.buffer().colours, [1, 2, 9]);
        assert!(viewer.buffer().info.is_some_and(|i| i.is_final));
    }

    #[test]
    fn out_of_order_messages_are_protocol_errors() {
        let mut viewer = Viewer::default();
        assert_eq!(
            viewer.receive(&full(1, vec![1])),
            Err(ProtocolError::BeforeHello)
        );
        viewer.receive(&hello(1)).unwrap();
        assert_eq!(viewer.receive(&hello(1)), Err(ProtocolError::SecondHello));
        assert_eq!(
            viewer.receive(&full(1, vec![1, 2])),
            Err(ProtocolError::PatchCount {
                expected: 1,
                got: 2
            })
        );
        assert!(matches!(
            viewer.receive(&[0xff]),
            Err(ProtocolError::Decode(_))
        ));
    }

    #[test]
    fn a_delta_on_a_foreign_base_asks_for_a_full_frame() {
        let mut viewer = Viewer::default();
        viewer.receive(&hello(2)).unwrap();
        viewer.receive(&full(5, vec![1, 2])).unwrap();
        assert_eq!(
            viewer.receive(&delta(4, 6, 2, &[(0, 3)])),
            Ok(Step::NeedsFull)
        );
        assert_eq!(viewer.buffer().colours, [1, 2], "nothing applied");
    }

    #[test]
    fn a_geometry_change_lets_the_next_full_frame_set_the_vertex_count() {
        let mut viewer = Viewer::default();
        viewer.receive(&hello(2)).unwrap();
        viewer.receive(&full(1, vec![1, 2])).unwrap();
        assert_eq!(
            viewer.receive(
                &ServerMessage::GeometryChanged {
                    geometry_version: 2
                }
                .encode()
            ),
            Ok(Step::GeometryChanged {
                geometry_version: 2
            })
        );
        assert_eq!(viewer.geometry_version(), 2);
        viewer.receive(&full(2, vec![4, 5, 6, 7])).unwrap();
        assert_eq!(viewer.buffer().colours, [4, 5, 6, 7]);
        // From then on, frames of the old count are refused.
        assert_eq!(
            viewer.receive(&full(3, vec![1, 2])),
            Err(ProtocolError::PatchCount {
                expected: 4,
                got: 2
            })
        );
    }
}

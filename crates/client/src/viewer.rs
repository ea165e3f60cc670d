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
        /// Which kind.
        frame: Frame,
        /// Vertices whose value changed (for a sum: the terms it adds up).
        changed: usize,
        /// What the frame says of the state now held.
        info: FrameInfo,
    },
    /// Protocol 3: a response was kept for the sums to come.
    Response {
        /// Its id.
        response_id: u32,
    },
    /// A delta against a state this viewer does not hold: send
    /// [`wire::ClientMessage::RequestFull`] and wait.
    NeedsFull,
}

/// The kinds of frame that set the state a viewer holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Frame {
    /// Every vertex's code.
    Full,
    /// The codes that changed.
    Delta,
    /// Protocol 3: a weighted sum of responses.
    Sum,
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
    /// A response or a sum on a connection that did not negotiate protocol 3.
    #[error("a protocol-3 message on a protocol-{0} connection")]
    NotNegotiated(u16),
    /// A sum the responses held cannot make.
    #[error("{0}")]
    Sum(#[from] wire::responses::SumError),
}

impl Viewer {
    /// Decodes and applies one binary message from the server.
    pub fn receive(&mut self, bytes: &[u8]) -> Result<Step, ProtocolError> {
        let message = ServerMessage::decode(bytes)?;
        let hello = match (&message, self.hello) {
            (ServerMessage::Hello(hello), None) => {
                self.hello = Some(*hello);
                self.geometry_version = hello.geometry_version;
                self.expected_vertices = Some(hello.vertex_count);
                return Ok(Step::Hello(*hello));
            }
            (ServerMessage::Hello(_), Some(_)) => return Err(ProtocolError::SecondHello),
            (_, None) => return Err(ProtocolError::BeforeHello),
            (_, Some(hello)) => hello,
        };
        let (frame, info, changed) = match &message {
            ServerMessage::Hello(_) => unreachable!("handled above"),
            ServerMessage::GeometryChanged { geometry_version } => {
                self.geometry_version = *geometry_version;
                self.expected_vertices = None;
                self.apply(&message)?;
                return Ok(Step::GeometryChanged {
                    geometry_version: *geometry_version,
                });
            }
            ServerMessage::Response(response) => {
                self.negotiated(hello)?;
                self.check_count(response.codes.len() as u32)?;
                self.apply(&message)?;
                return Ok(Step::Response {
                    response_id: response.response_id,
                });
            }
            ServerMessage::Full(frame) => {
                let changed = if self.buffer.colours.len() == frame.colours.len() {
                    wire::changes(&self.buffer.colours, &frame.colours).0.len()
                } else {
                    frame.colours.len()
                };
                (Frame::Full, frame.info, changed)
            }
            ServerMessage::Delta(frame) => (Frame::Delta, frame.info, frame.indices.len()),
            ServerMessage::Sum(sum) => {
                self.negotiated(hello)?;
                (Frame::Sum, sum.info, sum.terms.len())
            }
        };
        self.check_count(info.vertex_count)?;
        match self.buffer.apply(&message) {
            Ok(()) => {}
            Err(ApplyError::BaseMismatch { .. }) => return Ok(Step::NeedsFull),
            Err(ApplyError::Sum(error)) => return Err(error.into()),
        }
        if frame != Frame::Delta {
            self.expected_vertices = Some(info.vertex_count);
        }
        Ok(Step::Applied {
            frame,
            changed,
            info,
        })
    }

    /// Applies a message that sets no version (a response, a geometry change).
    fn apply(&mut self, message: &ServerMessage) -> Result<(), ProtocolError> {
        match self.buffer.apply(message) {
            Err(ApplyError::Sum(error)) => Err(error.into()),
            _ => Ok(()),
        }
    }

    /// Refuses a protocol-3 message unless the hello said 3.
    fn negotiated(&self, hello: Hello) -> Result<(), ProtocolError> {
        match hello.protocol_version >= 3 {
            true => Ok(()),
            false => Err(ProtocolError::NotNegotiated(hello.protocol_version)),
        }
    }

    /// Refuses a vertex count other than the geometry's (unknown after a geometry change).
    fn check_count(&self, got: u32) -> Result<(), ProtocolError> {
        match self.expected_vertices {
            Some(expected) if expected != got => Err(ProtocolError::PatchCount { expected, got }),
            _ => Ok(()),
        }
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
                frame: Frame::Full,
                changed: 3,
                ..
            }
        ));
        let step = viewer.receive(&delta(1, 2, 3, &[(2, 9)])).unwrap();
        assert!(matches!(
            step,
            Step::Applied {
                frame: Frame::Delta,
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

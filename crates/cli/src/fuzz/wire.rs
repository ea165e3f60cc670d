//! The wire target: mutated server messages, geometry and client messages go through every
//! decoder, and what decodes goes on into a viewer's colour buffer (after a valid full frame,
//! so deltas are applied for real) and the display's exposure. Checked: no panic, and a
//! buffer that accepted a frame decodes to finite radiosity.

use super::mutate::{Choices, mutate_bytes};
use super::{Input, Outcome, Target};
use std::path::Path;
use wire::{
    ClientMessage, ColourBuffer, DeltaFrame, FrameInfo, FullFrame, Geometry, Hello, ServerMessage,
    geometry::NO_CORNER,
};

/// Valid encodings of every message kind, compressed and not.
pub struct WireTarget {
    corpus: Vec<Vec<u8>>,
    /// What a viewer holds before the mutated message arrives.
    held: ColourBuffer,
}

const VERTICES: u32 = 64;

fn info(version: u64, scale: f32) -> FrameInfo {
    FrameInfo {
        solution_version: version,
        sent_at_unix_micros: 1_700_000_000_000_000,
        scale,
        vertex_count: VERTICES,
        is_final: version % 2 == 0,
    }
}

impl Default for WireTarget {
    fn default() -> Self {
        let smooth: Vec<u32> = (0..VERTICES)
            .map(|i| wire::encode_colour([i as f32, 1.0, 0.5], 1.0))
            .collect();
        // Noise does not compress: the frame goes raw.
        let noisy: Vec<u32> = (0..VERTICES)
            .map(|i| (i.wrapping_mul(2_654_435_761)) ^ 0x5bd1_e995)
            .collect();
        let full = FullFrame {
            info: info(1, 1.0),
            colours: smooth.clone(),
        };
        let messages = [
            ServerMessage::Hello(Hello {
                protocol_version: wire::PROTOCOL_VERSION,
                scene_id: 42,
                geometry_version: 1,
                vertex_count: VERTICES,
            }),
            ServerMessage::Full(full.clone()),
            ServerMessage::Full(FullFrame {
                info: info(2, 0.25),
                colours: noisy,
            }),
            ServerMessage::Delta(DeltaFrame {
                base_version: 1,
                info: info(2, 1.0),
                indices: vec![0, 5, 63],
                colours: vec![7, 8, 9],
            }),
            ServerMessage::GeometryChanged {
                geometry_version: 2,
            },
        ];
        let geometry = Geometry {
            positions: (0..VERTICES)
                .map(|i| [i as f32, (i % 3) as f32, 0.5])
                .collect(),
            patches: (0..VERTICES - 3)
                .map(|i| match i % 2 {
                    0 => [i, i + 1, i + 2, NO_CORNER],
                    _ => [i, i + 1, i + 2, i + 3],
                })
                .collect(),
            patch_objects: (0..VERTICES - 3).map(|i| i % 2).collect(),
            objects: vec!["floor".into(), "light".into()],
            camera: None,
            textures: None,
        };
        let mut corpus: Vec<Vec<u8>> = messages.iter().map(ServerMessage::encode).collect();
        corpus.push(geometry.encode());
        corpus.push(ClientMessage::RequestFull.encode());
        let mut held = ColourBuffer::default();
        held.apply(&ServerMessage::Full(full))
            .expect("a full frame always applies");
        WireTarget { corpus, held }
    }
}

impl Target for WireTarget {
    fn name(&self) -> &'static str {
        "wire"
    }

    fn input(&self, choices: &mut Choices) -> Input {
        let mut bytes = choices.pick(&self.corpus).clone();
        for _ in 0..1 + choices.below(4) {
            let other = choices.pick(&self.corpus).clone();
            bytes = mutate_bytes(&bytes, &other, choices);
        }
        vec![("message.bin".into(), bytes)]
    }

    fn run(&self, input: &Input, _scratch: &Path) -> Result<Outcome, String> {
        let bytes = &input[0].1;
        let mut decoded = false;
        let _ = ClientMessage::decode(bytes).map(|_| decoded = true);
        if let Ok(geometry) = Geometry::decode(bytes) {
            decoded = true;
            let radiosity = vec![[1.0f32; 3]; geometry.positions.len()];
            let emitting: Vec<bool> = (0..geometry.objects.len()).map(|o| o % 2 == 0).collect();
            let exposure = wire::display::exposure(&geometry, &radiosity, &emitting);
            if !exposure.is_finite() {
                return Err(format!("exposure {exposure} of a decoded geometry"));
            }
        }
        if let Ok(message) = ServerMessage::decode(bytes) {
            decoded = true;
            let mut buffer = self.held.clone();
            if buffer.apply(&message).is_ok() {
                let finite = buffer.radiosity().iter().flatten().all(|c| c.is_finite());
                if !finite {
                    return Err(format!(
                        "a frame that decodes to non-finite radiosity: {message:?}"
                    ));
                }
            }
        }
        Ok(match decoded {
            true => Outcome::Accepted,
            false => Outcome::Rejected,
        })
    }
}

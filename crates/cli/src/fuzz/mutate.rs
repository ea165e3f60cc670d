//! Seeded mutations: byte-level for binary messages, token- and line-level for text scenes,
//! each biased toward the values that break numeric and parsing code (NaN, infinities,
//! huge and tiny magnitudes, lengths and indices at their limits).

use rand_core::{RngCore, SeedableRng};
use rand_pcg::Pcg64;

/// A reproducible stream of choices: case `case` of seed `seed` is always the same.
pub struct Choices(Pcg64);

impl Choices {
    /// The stream for one case.
    pub fn new(seed: u64, case: u64) -> Choices {
        // Distinct streams per case: the case number goes into the seed, not the stream order.
        Choices(Pcg64::seed_from_u64(
            seed ^ case.wrapping_mul(0x9E37_79B9_7F4A_7C15),
        ))
    }

    /// A number in `0..n` (`n` > 0).
    pub fn below(&mut self, n: usize) -> usize {
        (self.0.next_u64() % n as u64) as usize
    }

    /// One of `items`.
    pub fn pick<'a, T>(&mut self, items: &'a [T]) -> &'a T {
        &items[self.below(items.len())]
    }

    /// A random byte.
    fn byte(&mut self) -> u8 {
        self.0.next_u64() as u8
    }
}

/// Numbers that break parsers and arithmetic, as scene-file text.
const HOSTILE_NUMBERS: &[&str] = &[
    "nan",
    "NaN",
    "inf",
    "-inf",
    "1e308",
    "-1e308",
    "1e39",
    "3e38",
    "1e17",
    "1e-320",
    "-0",
    "0",
    "1",
    "-1",
    "0.999999",
    "1.0000001",
    "4294967295",
    "2147483648",
    "-2147483649",
    "99999999999999999999",
    "1e",
    ".",
    "-",
    "0x10",
    "",
];

/// Applies one text mutation to `text`: a number replaced by a hostile one, a token or line
/// dropped, duplicated or swapped, a line cut short, every coordinate scaled, bytes spliced.
pub fn mutate_text(text: &[u8], choices: &mut Choices) -> Vec<u8> {
    let text = String::from_utf8_lossy(text);
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    if lines.is_empty() {
        return mutate_bytes(text.as_bytes(), &[], choices);
    }
    let at = choices.below(lines.len());
    match choices.below(8) {
        0 | 1 => {
            let mut tokens: Vec<String> =
                lines[at].split_whitespace().map(str::to_string).collect();
            if !tokens.is_empty() {
                let t = choices.below(tokens.len());
                tokens[t] = choices.pick(HOSTILE_NUMBERS).to_string();
            }
            lines[at] = tokens.join(" ");
        }
        2 => {
            let mut tokens: Vec<&str> = lines[at].split_whitespace().collect();
            tokens.truncate(choices.below(tokens.len().max(1)));
            lines[at] = tokens.join(" ");
        }
        3 => {
            let copy = lines[at].clone();
            lines.insert(choices.below(lines.len() + 1), copy);
        }
        4 => {
            lines.remove(at);
        }
        5 => {
            let other = choices.below(lines.len());
            lines.swap(at, other);
        }
        6 => {
            // Scale the whole scene: what the solver must stay exact under, or refuse.
            let factor = *choices.pick(&[1e-20, 1e-14, 1e-10, 1e10, 1e17, 1e20, 1e30, 1e40]);
            for line in lines.iter_mut().filter(|l| l.starts_with("v ")) {
                let scaled: Vec<String> = line
                    .split_whitespace()
                    .skip(1)
                    .map(|t| {
                        t.parse::<f64>()
                            .map_or(t.to_string(), |v| format!("{:e}", v * factor))
                    })
                    .collect();
                *line = format!("v {}", scaled.join(" "));
            }
        }
        _ => return mutate_bytes(lines.join("\n").as_bytes(), &[], choices),
    }
    lines.join("\n").into_bytes()
}

/// Applies one byte mutation: a bit flipped, a byte set, bytes inserted, removed, duplicated
/// or overwritten with a hostile 32-bit value, a cut, or a splice from `other`.
pub fn mutate_bytes(bytes: &[u8], other: &[u8], choices: &mut Choices) -> Vec<u8> {
    let mut out = bytes.to_vec();
    if out.is_empty() {
        out.push(choices.byte());
        return out;
    }
    let at = choices.below(out.len());
    match choices.below(8) {
        0 => out[at] ^= 1 << choices.below(8),
        1 => out[at] = choices.byte(),
        2 => {
            let count = 1 + choices.below(16);
            let fresh: Vec<u8> = (0..count).map(|_| choices.byte()).collect();
            out.splice(at..at, fresh);
        }
        3 => {
            let end = (at + 1 + choices.below(64)).min(out.len());
            out.drain(at..end);
        }
        4 => {
            let end = (at + 1 + choices.below(64)).min(out.len());
            let copy = out[at..end].to_vec();
            out.splice(at..at, copy);
        }
        5 => {
            let value: u32 = *choices.pick(&[
                0,
                1,
                0x7F,
                0xFF,
                0xFFFF,
                0x7FFF_FFFF,
                0xFFFF_FFFF,
                1 << 24,
                0x7F80_0000,
                0x7FC0_0000,
            ]);
            let end = (at + 4).min(out.len());
            out[at..end].copy_from_slice(&value.to_le_bytes()[..end - at]);
        }
        6 => out.truncate(at),
        _ => {
            if other.is_empty() {
                out.truncate(at);
            } else {
                let from = choices.below(other.len());
                out.truncate(at);
                out.extend_from_slice(&other[from..]);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_case_is_reproducible_and_cases_differ() {
        let text = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
        let run = |case| {
            let mut choices = Choices::new(7, case);
            (0..4).fold(text.to_vec(), |t, _| mutate_text(&t, &mut choices))
        };
        assert_eq!(run(3), run(3));
        assert!(
            (0..20)
                .map(run)
                .collect::<std::collections::HashSet<_>>()
                .len()
                > 10
        );
    }
}

//! The LCUS/CH340 relay protocol as a module hears it: `[0xA0, channel, state, sum]`, state
//! 1 = closed, sum the low byte of the first three. One decoder for every simulated LCUS
//! module (the lab's relay and the test emulators).

/// What a stream of bytes said.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Heard {
    /// A valid frame: (channel, closed).
    Switch { channel: u8, closed: bool },
    /// A byte that did not start a valid frame (dropped to resynchronise).
    Bad,
}

/// Takes the complete frames (and bad bytes) off the front of `pending`; an incomplete frame
/// stays for the next bytes.
pub fn decode(pending: &mut Vec<u8>) -> Vec<Heard> {
    let mut out = Vec::new();
    while pending.len() >= 4 {
        let f = [pending[0], pending[1], pending[2], pending[3]];
        let sum = f[0].wrapping_add(f[1]).wrapping_add(f[2]);
        if f[0] == 0xA0 && f[2] <= 1 && f[3] == sum {
            out.push(Heard::Switch {
                channel: f[1],
                closed: f[2] == 1,
            });
            pending.drain(..4);
        } else {
            pending.remove(0);
            out.push(Heard::Bad);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_are_decoded_and_garbage_skipped() {
        let mut p = vec![0x00, 0xA0, 0x01, 0x01, 0xA2, 0xA0, 0x02, 0x00, 0xA2, 0xA0];
        let heard = decode(&mut p);
        assert_eq!(
            heard,
            vec![
                Heard::Bad,
                Heard::Switch {
                    channel: 1,
                    closed: true
                },
                Heard::Switch {
                    channel: 2,
                    closed: false
                },
            ]
        );
        assert_eq!(p, vec![0xA0]);
    }
}

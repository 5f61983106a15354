//! Client → robot commands: argument encoding (docs §2) and the typed command set (docs §4).

use thiserror::Error;

use crate::frame::Frame;

/// Argument type byte: non-negative integer (docs §2).
pub const ARG_INT: u8 = 0x3B;
/// Argument type byte: negative integer, magnitude follows (docs §2).
pub const ARG_NINT: u8 = 0x1B;
/// Argument type byte: length-prefixed string (docs §2).
pub const ARG_STR: u8 = 0x2B;

/// Command numbers used by this crate (docs §4).
pub mod number {
    /// SYNC0 before the connection is open, PULSE after.
    pub const SYNC0_PULSE: u8 = 0;
    /// SYNC1 before the connection is open, OPEN after.
    pub const SYNC1_OPEN: u8 = 1;
    /// SYNC2 before the connection is open, CLOSE after.
    pub const SYNC2_CLOSE: u8 = 2;
    /// ENABLE motors (int 1/0).
    pub const ENABLE: u8 = 4;
    /// SETA translational acceleration (+) / deceleration (−), mm/s².
    pub const SETA: u8 = 5;
    /// SETV maximum translational velocity, mm/s.
    pub const SETV: u8 = 6;
    /// SETO reset odometry origin.
    pub const SETO: u8 = 7;
    /// SETRV maximum rotational velocity, deg/s.
    pub const SETRV: u8 = 10;
    /// VEL translational velocity, mm/s.
    pub const VEL: u8 = 11;
    /// HEAD absolute heading, degrees.
    pub const HEAD: u8 = 12;
    /// DHEAD relative heading, degrees.
    pub const DHEAD: u8 = 13;
    /// CONFIG request.
    pub const CONFIG: u8 = 18;
    /// RVEL rotational velocity, deg/s, counter-clockwise positive.
    pub const RVEL: u8 = 21;
    /// SETRA rotational acceleration (+) / deceleration (−), deg/s².
    pub const SETRA: u8 = 23;
    /// SONAR enable (1) / disable (0).
    pub const SONAR: u8 = 28;
    /// STOP.
    pub const STOP: u8 = 29;
    /// VEL2 independent wheel velocities: high byte left, low byte right.
    pub const VEL2: u8 = 32;
    /// ESTOP emergency stop.
    pub const ESTOP: u8 = 55;
}

/// A command argument.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Arg {
    /// No argument.
    None,
    /// A 16-bit sign-magnitude integer: −65535..=65535 fits the wire format; commands use the
    /// C `short` range −32768..=32767.
    Int(i32),
    /// A length-prefixed string (no trailing NUL is written).
    Str(Vec<u8>),
}

/// An argument that could not be decoded or encoded.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum ArgError {
    /// Unknown argument type byte.
    #[error("unknown argument type {ty:#04X} in {payload:02X?}")]
    UnknownType {
        /// The type byte.
        ty: u8,
        /// The whole payload.
        payload: Vec<u8>,
    },
    /// The argument is shorter than its type requires.
    #[error("truncated argument {payload:02X?}")]
    Truncated {
        /// The whole payload.
        payload: Vec<u8>,
    },
    /// Integer magnitude does not fit 16 bits.
    #[error("integer {0} does not fit a 16-bit magnitude")]
    IntOutOfRange(i32),
    /// String longer than 255 bytes.
    #[error("string of {0} bytes does not fit a one-byte length")]
    StrTooLong(usize),
    /// The argument makes the frame too long.
    #[error(transparent)]
    Frame(#[from] crate::frame::EncodeError),
}

impl Arg {
    /// Encodes the argument into a command payload (type byte + value).
    ///
    /// # Errors
    /// [`ArgError::IntOutOfRange`] or [`ArgError::StrTooLong`].
    pub fn encode(&self) -> Result<Vec<u8>, ArgError> {
        match self {
            Arg::None => Ok(Vec::new()),
            Arg::Int(v) => {
                let mag =
                    u16::try_from(v.unsigned_abs()).map_err(|_| ArgError::IntOutOfRange(*v))?;
                let ty = if *v >= 0 { ARG_INT } else { ARG_NINT };
                let [lo, hi] = mag.to_le_bytes();
                Ok(vec![ty, lo, hi])
            }
            Arg::Str(s) => {
                let len = u8::try_from(s.len()).map_err(|_| ArgError::StrTooLong(s.len()))?;
                let mut out = vec![ARG_STR, len];
                out.extend_from_slice(s);
                Ok(out)
            }
        }
    }

    /// Decodes a command payload. Bytes after a complete integer, or after a string's declared
    /// length (such as the trailing NUL some clients add), are ignored.
    ///
    /// # Errors
    /// [`ArgError::UnknownType`] or [`ArgError::Truncated`], carrying the payload.
    pub fn decode(payload: &[u8]) -> Result<Arg, ArgError> {
        let Some((ty, rest)) = payload.split_first() else {
            return Ok(Arg::None);
        };
        let truncated = || ArgError::Truncated {
            payload: payload.to_vec(),
        };
        match *ty {
            ARG_INT | ARG_NINT => {
                let mag = match rest {
                    [lo, hi, ..] => i32::from(u16::from_le_bytes([*lo, *hi])),
                    _ => return Err(truncated()),
                };
                Ok(Arg::Int(if *ty == ARG_NINT { -mag } else { mag }))
            }
            ARG_STR => {
                let (len, chars) = rest.split_first().ok_or_else(truncated)?;
                let s = chars.get(..usize::from(*len)).ok_or_else(truncated)?;
                Ok(Arg::Str(s.to_vec()))
            }
            ty => Err(ArgError::UnknownType {
                ty,
                payload: payload.to_vec(),
            }),
        }
    }
}

/// Limits applied to command values before they are encoded. Values outside are clamped and a
/// `tracing::warn!` event is emitted; nothing out of range reaches the wire.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CommandLimits {
    /// Largest |VEL| and SETV, mm/s.
    pub max_trans_vel: i16,
    /// Largest |RVEL| and SETRV, deg/s.
    pub max_rot_vel: i16,
    /// Largest |SETA|, mm/s².
    pub max_trans_accel: i16,
    /// Largest |SETRA|, deg/s².
    pub max_rot_accel: i16,
}

impl CommandLimits {
    /// P3-DX absolute limits from ARIA's parameters (MaxVelocity 2200 mm/s, MaxRVelocity
    /// 500 deg/s, docs §6.1); accelerations are limited only by the argument range.
    pub const P3DX: CommandLimits = CommandLimits {
        max_trans_vel: 2200,
        max_rot_vel: 500,
        max_trans_accel: i16::MAX,
        max_rot_accel: i16::MAX,
    };
    /// Only the argument range (±32767).
    pub const ARGUMENT_RANGE: CommandLimits = CommandLimits {
        max_trans_vel: i16::MAX,
        max_rot_vel: i16::MAX,
        max_trans_accel: i16::MAX,
        max_rot_accel: i16::MAX,
    };
}

impl Default for CommandLimits {
    fn default() -> Self {
        Self::P3DX
    }
}

/// Clamps `v` into `lo..=hi`, warning when it had to.
fn clamp_warn(what: &'static str, v: i16, lo: i16, hi: i16) -> i16 {
    let c = v.clamp(lo, hi);
    if c != v {
        tracing::warn!(
            command = what,
            requested = v,
            sent = c,
            "ARIA command value clamped"
        );
    }
    c
}

/// Converts a physical value to the nearest `i16`, clamping (with a warning) when it does not
/// fit; NaN becomes 0.
#[must_use]
pub fn to_i16_clamped(what: &'static str, v: f64) -> i16 {
    let r = v.round();
    if r.is_nan() {
        tracing::warn!(command = what, "ARIA command value is NaN, sending 0");
        return 0;
    }
    let c = r.clamp(f64::from(i16::MIN), f64::from(i16::MAX));
    if c != r {
        tracing::warn!(
            command = what,
            requested = v,
            sent = c,
            "ARIA command value clamped"
        );
    }
    // In range after the clamp.
    c as i16
}

/// Converts a wheel speed (mm/s) to a VEL2 byte in units of `divisor` mm/s, clamping to the
/// signed byte range with a warning.
#[must_use]
pub fn vel2_units(what: &'static str, mm_s: f64, divisor: f64) -> i8 {
    let u = to_i16_clamped(what, mm_s / divisor);
    let c = u.clamp(i16::from(i8::MIN), i16::from(i8::MAX));
    if c != u {
        tracing::warn!(
            command = what,
            requested = u,
            sent = c,
            "ARIA VEL2 value clamped"
        );
    }
    i8::try_from(c).unwrap_or(0)
}

/// A typed client command (docs §4). Values are in the robot's units: mm, mm/s, mm/s², deg,
/// deg/s, deg/s².
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Command {
    /// Handshake step 0 (same bytes as [`Command::Pulse`]).
    Sync0,
    /// Handshake step 1 (same bytes as [`Command::Open`]).
    Sync1,
    /// Handshake step 2 (same bytes as [`Command::Close`]).
    Sync2,
    /// Start the servers and the SIP stream.
    Open,
    /// Watchdog keep-alive.
    Pulse,
    /// Close the connection; motors and sonar off.
    Close,
    /// Enable (true) or disable the motors.
    Enable(bool),
    /// Translational velocity, mm/s, forward positive.
    Vel(i16),
    /// Rotational velocity, deg/s, counter-clockwise positive.
    Rvel(i16),
    /// Wheel velocities in VEL2 units (20 mm/s on a P3).
    Vel2 {
        /// Left wheel.
        left: i8,
        /// Right wheel.
        right: i8,
    },
    /// Turn to an absolute heading, degrees 0..=359.
    Head(i16),
    /// Turn relative to the current heading, degrees.
    Dhead(i16),
    /// Maximum translational velocity, mm/s (non-negative).
    SetV(i16),
    /// Maximum rotational velocity, deg/s (non-negative).
    SetRv(i16),
    /// Translational acceleration (+) or deceleration (−), mm/s².
    SetA(i16),
    /// Rotational acceleration (+) or deceleration (−), deg/s².
    SetRa(i16),
    /// Stop (decelerating normally).
    Stop,
    /// Emergency stop.
    EStop,
    /// Sonar on (true) or off.
    Sonar(bool),
    /// Reset the odometry origin to (0, 0, 0).
    SetO,
    /// Request one CONFIG packet.
    Config,
    /// Any other command number with its argument.
    Other {
        /// Command number.
        number: u8,
        /// Argument.
        arg: Arg,
    },
}

/// A command frame that could not be interpreted.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum CommandError {
    /// The argument is malformed.
    #[error("command {number}: {source}")]
    Arg {
        /// Command number.
        number: u8,
        /// What was wrong.
        source: ArgError,
    },
    /// The command needs an integer argument and got something else.
    #[error("command {number} needs an integer argument, got {arg:?}")]
    NeedsInt {
        /// Command number.
        number: u8,
        /// The argument received.
        arg: Arg,
    },
}

/// Whether the robot-side connection is open; decides how commands 0, 1 and 2 are read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkPhase {
    /// Before OPEN: commands 0..2 are SYNC0..SYNC2.
    Handshake,
    /// After OPEN: commands 0..2 are PULSE, OPEN, CLOSE.
    Open,
}

impl Command {
    /// The command number and argument after clamping to `limits` (warning on every clamp).
    #[must_use]
    pub fn number_and_arg(&self, limits: &CommandLimits) -> (u8, Arg) {
        use number as n;
        let int = |v: i16| Arg::Int(i32::from(v));
        let tv = limits.max_trans_vel.max(0);
        let rv = limits.max_rot_vel.max(0);
        let ta = limits.max_trans_accel.max(0);
        let ra = limits.max_rot_accel.max(0);
        match self {
            Command::Sync0 | Command::Pulse => (n::SYNC0_PULSE, Arg::None),
            Command::Sync1 | Command::Open => (n::SYNC1_OPEN, Arg::None),
            Command::Sync2 | Command::Close => (n::SYNC2_CLOSE, Arg::None),
            Command::Enable(on) => (n::ENABLE, Arg::Int(i32::from(*on))),
            Command::Vel(v) => (n::VEL, int(clamp_warn("VEL", *v, -tv, tv))),
            Command::Rvel(v) => (n::RVEL, int(clamp_warn("RVEL", *v, -rv, rv))),
            Command::Vel2 { left, right } => {
                // Packed as ARIA's com2Bytes: a 16-bit pattern, sent sign-magnitude.
                let packed = i16::from_be_bytes([left.to_be_bytes()[0], right.to_be_bytes()[0]]);
                (n::VEL2, int(packed))
            }
            Command::Head(h) => {
                let w = h.rem_euclid(360);
                if w != *h {
                    tracing::warn!(requested = h, sent = w, "ARIA HEAD wrapped into 0..359");
                }
                (n::HEAD, int(w))
            }
            Command::Dhead(d) => (n::DHEAD, int(clamp_warn("DHEAD", *d, -i16::MAX, i16::MAX))),
            Command::SetV(v) => (n::SETV, int(clamp_warn("SETV", *v, 0, tv))),
            Command::SetRv(v) => (n::SETRV, int(clamp_warn("SETRV", *v, 0, rv))),
            Command::SetA(a) => (n::SETA, int(clamp_warn("SETA", *a, -ta, ta))),
            Command::SetRa(a) => (n::SETRA, int(clamp_warn("SETRA", *a, -ra, ra))),
            Command::Stop => (n::STOP, Arg::None),
            Command::EStop => (n::ESTOP, Arg::None),
            Command::Sonar(on) => (n::SONAR, Arg::Int(i32::from(*on))),
            Command::SetO => (n::SETO, Arg::None),
            Command::Config => (n::CONFIG, Arg::None),
            Command::Other { number, arg } => (*number, arg.clone()),
        }
    }

    /// The frame for this command after clamping to `limits`.
    ///
    /// # Errors
    /// Only [`Command::Other`] can fail (an argument that does not fit).
    pub fn to_frame(&self, limits: &CommandLimits) -> Result<Frame, ArgError> {
        let (number, arg) = self.number_and_arg(limits);
        Ok(Frame::new(number, arg.encode()?))
    }

    /// The bytes on the wire for this command after clamping to `limits`.
    ///
    /// # Errors
    /// Only [`Command::Other`] can fail (an argument or frame that does not fit).
    pub fn encode(&self, limits: &CommandLimits) -> Result<Vec<u8>, ArgError> {
        Ok(self.to_frame(limits)?.encode()?)
    }

    /// Interprets a received command frame (robot side). Integer arguments outside the `i16`
    /// range saturate.
    ///
    /// # Errors
    /// [`CommandError`] for a malformed argument or a missing integer argument.
    pub fn from_frame(frame: &Frame, phase: LinkPhase) -> Result<Command, CommandError> {
        use number as n;
        let number = frame.id;
        let arg =
            Arg::decode(&frame.payload).map_err(|source| CommandError::Arg { number, source })?;
        let int = || match &arg {
            Arg::Int(v) => {
                Ok(i16::try_from(*v).unwrap_or(if *v < 0 { i16::MIN } else { i16::MAX }))
            }
            other => Err(CommandError::NeedsInt {
                number,
                arg: other.clone(),
            }),
        };
        let open = phase == LinkPhase::Open;
        Ok(match number {
            n::SYNC0_PULSE if open => Command::Pulse,
            n::SYNC0_PULSE => Command::Sync0,
            n::SYNC1_OPEN if open => Command::Open,
            n::SYNC1_OPEN => Command::Sync1,
            n::SYNC2_CLOSE if open => Command::Close,
            n::SYNC2_CLOSE => Command::Sync2,
            n::ENABLE => Command::Enable(int()? != 0),
            n::VEL => Command::Vel(int()?),
            n::RVEL => Command::Rvel(int()?),
            n::VEL2 => {
                // Undo the sign-magnitude: the 16-bit pattern is the two's-complement value.
                let raw = match &arg {
                    Arg::Int(v) => *v as u16,
                    other => {
                        return Err(CommandError::NeedsInt {
                            number,
                            arg: other.clone(),
                        })
                    }
                };
                let [hi, lo] = raw.to_be_bytes();
                Command::Vel2 {
                    left: i8::from_be_bytes([hi]),
                    right: i8::from_be_bytes([lo]),
                }
            }
            n::HEAD => Command::Head(int()?),
            n::DHEAD => Command::Dhead(int()?),
            n::SETV => Command::SetV(int()?),
            n::SETRV => Command::SetRv(int()?),
            n::SETA => Command::SetA(int()?),
            n::SETRA => Command::SetRa(int()?),
            n::STOP => Command::Stop,
            n::ESTOP => Command::EStop,
            n::SONAR => Command::Sonar(int()? & 1 == 1),
            n::SETO => Command::SetO,
            n::CONFIG => Command::Config,
            number => Command::Other { number, arg },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bytes(c: Command) -> Vec<u8> {
        c.encode(&CommandLimits::P3DX).unwrap()
    }

    #[test]
    fn handshake_and_connection_commands() {
        // docs/protocols/pioneer-aria.md §8 Example A and "More verified command packets".
        assert_eq!(bytes(Command::Sync0), [0xFA, 0xFB, 0x03, 0x00, 0x00, 0x00]);
        assert_eq!(bytes(Command::Pulse), [0xFA, 0xFB, 0x03, 0x00, 0x00, 0x00]);
        assert_eq!(bytes(Command::Sync1), [0xFA, 0xFB, 0x03, 0x01, 0x00, 0x01]);
        assert_eq!(bytes(Command::Open), [0xFA, 0xFB, 0x03, 0x01, 0x00, 0x01]);
        assert_eq!(bytes(Command::Sync2), [0xFA, 0xFB, 0x03, 0x02, 0x00, 0x02]);
        assert_eq!(bytes(Command::Close), [0xFA, 0xFB, 0x03, 0x02, 0x00, 0x02]);
    }

    #[test]
    fn enable_commands() {
        // §8 Example B and table row "ENABLE 0".
        assert_eq!(
            bytes(Command::Enable(true)),
            [0xFA, 0xFB, 0x06, 0x04, 0x3B, 0x01, 0x00, 0x05, 0x3B]
        );
        assert_eq!(
            bytes(Command::Enable(false)),
            [0xFA, 0xFB, 0x06, 0x04, 0x3B, 0x00, 0x00, 0x04, 0x3B]
        );
    }

    #[test]
    fn velocity_commands() {
        // §8 Examples C, D and table rows VEL 0, VEL 1000, RVEL ±30, RVEL 0.
        assert_eq!(
            bytes(Command::Vel(200)),
            [0xFA, 0xFB, 0x06, 0x0B, 0x3B, 0xC8, 0x00, 0xD3, 0x3B]
        );
        assert_eq!(
            bytes(Command::Vel(-200)),
            [0xFA, 0xFB, 0x06, 0x0B, 0x1B, 0xC8, 0x00, 0xD3, 0x1B]
        );
        assert_eq!(
            bytes(Command::Vel(0)),
            [0xFA, 0xFB, 0x06, 0x0B, 0x3B, 0x00, 0x00, 0x0B, 0x3B]
        );
        assert_eq!(
            bytes(Command::Vel(1000)),
            [0xFA, 0xFB, 0x06, 0x0B, 0x3B, 0xE8, 0x03, 0xF3, 0x3E]
        );
        assert_eq!(
            bytes(Command::Rvel(30)),
            [0xFA, 0xFB, 0x06, 0x15, 0x3B, 0x1E, 0x00, 0x33, 0x3B]
        );
        assert_eq!(
            bytes(Command::Rvel(-30)),
            [0xFA, 0xFB, 0x06, 0x15, 0x1B, 0x1E, 0x00, 0x33, 0x1B]
        );
        assert_eq!(
            bytes(Command::Rvel(0)),
            [0xFA, 0xFB, 0x06, 0x15, 0x3B, 0x00, 0x00, 0x15, 0x3B]
        );
    }

    #[test]
    fn vel2_packs_left_high_right_low() {
        // §4 row VEL2: high byte left, low byte right; §2 com2Bytes sign-magnitude.
        // left 10, right 5 → 0x0A05 = 2565 → `3B 05 0A`; checksum 0x203B + 0x050A = 0x2545.
        assert_eq!(
            bytes(Command::Vel2 { left: 10, right: 5 }),
            [0xFA, 0xFB, 0x06, 0x20, 0x3B, 0x05, 0x0A, 0x25, 0x45]
        );
        // left −1, right 0 → pattern 0xFF00 = −256 → NINT magnitude 0x0100 → `1B 00 01`;
        // checksum 0x201B + 0x0001 = 0x201C.
        assert_eq!(
            bytes(Command::Vel2 { left: -1, right: 0 }),
            [0xFA, 0xFB, 0x06, 0x20, 0x1B, 0x00, 0x01, 0x20, 0x1C]
        );
    }

    #[test]
    fn heading_and_limit_commands() {
        // §8 table rows HEAD 90, DHEAD −45, SETV 500, SETA −300, SETRV 100.
        assert_eq!(
            bytes(Command::Head(90)),
            [0xFA, 0xFB, 0x06, 0x0C, 0x3B, 0x5A, 0x00, 0x66, 0x3B]
        );
        assert_eq!(
            bytes(Command::Dhead(-45)),
            [0xFA, 0xFB, 0x06, 0x0D, 0x1B, 0x2D, 0x00, 0x3A, 0x1B]
        );
        assert_eq!(
            bytes(Command::SetV(500)),
            [0xFA, 0xFB, 0x06, 0x06, 0x3B, 0xF4, 0x01, 0xFA, 0x3C]
        );
        assert_eq!(
            bytes(Command::SetA(-300)),
            [0xFA, 0xFB, 0x06, 0x05, 0x1B, 0x2C, 0x01, 0x31, 0x1C]
        );
        assert_eq!(
            bytes(Command::SetRv(100)),
            [0xFA, 0xFB, 0x06, 0x0A, 0x3B, 0x64, 0x00, 0x6E, 0x3B]
        );
    }

    #[test]
    fn argumentless_commands() {
        // §8 table rows SETO, STOP, ESTOP, SONAR 0/1, CONFIG 1 (ARIA form) and CONFIG bare.
        assert_eq!(bytes(Command::SetO), [0xFA, 0xFB, 0x03, 0x07, 0x00, 0x07]);
        assert_eq!(bytes(Command::Stop), [0xFA, 0xFB, 0x03, 0x1D, 0x00, 0x1D]);
        assert_eq!(bytes(Command::EStop), [0xFA, 0xFB, 0x03, 0x37, 0x00, 0x37]);
        assert_eq!(
            bytes(Command::Sonar(false)),
            [0xFA, 0xFB, 0x06, 0x1C, 0x3B, 0x00, 0x00, 0x1C, 0x3B]
        );
        assert_eq!(
            bytes(Command::Sonar(true)),
            [0xFA, 0xFB, 0x06, 0x1C, 0x3B, 0x01, 0x00, 0x1D, 0x3B]
        );
        assert_eq!(bytes(Command::Config), [0xFA, 0xFB, 0x03, 0x12, 0x00, 0x12]);
        let config1 = Command::Other {
            number: number::CONFIG,
            arg: Arg::Int(1),
        };
        assert_eq!(
            bytes(config1),
            [0xFA, 0xFB, 0x06, 0x12, 0x3B, 0x01, 0x00, 0x13, 0x3B]
        );
    }

    #[test]
    fn reference_table_commands_through_other() {
        // §8 "More verified command packets": OPEN 1 and CLOSE 1 (ARIA form), ENCODER 2,
        // HOSTBAUD 4, MOVE 500.
        let other = |number, v| Command::Other {
            number,
            arg: Arg::Int(v),
        };
        assert_eq!(
            bytes(other(1, 1)),
            [0xFA, 0xFB, 0x06, 0x01, 0x3B, 0x01, 0x00, 0x02, 0x3B]
        );
        assert_eq!(
            bytes(other(2, 1)),
            [0xFA, 0xFB, 0x06, 0x02, 0x3B, 0x01, 0x00, 0x03, 0x3B]
        );
        assert_eq!(
            bytes(other(19, 2)),
            [0xFA, 0xFB, 0x06, 0x13, 0x3B, 0x02, 0x00, 0x15, 0x3B]
        );
        assert_eq!(
            bytes(other(50, 4)),
            [0xFA, 0xFB, 0x06, 0x32, 0x3B, 0x04, 0x00, 0x36, 0x3B]
        );
        assert_eq!(
            bytes(other(8, 500)),
            [0xFA, 0xFB, 0x06, 0x08, 0x3B, 0xF4, 0x01, 0xFC, 0x3C]
        );
        // The ARIA forms decode as the plain commands once the link is open.
        let f = Frame::new(1, vec![0x3B, 0x01, 0x00]);
        assert_eq!(Command::from_frame(&f, LinkPhase::Open), Ok(Command::Open));
    }

    #[test]
    fn string_argument_odd_length() {
        // §8 Example E: TTY2 "hi" with an odd number of data bytes.
        let tty2 = Command::Other {
            number: 0x2A,
            arg: Arg::Str(b"hi".to_vec()),
        };
        assert_eq!(
            bytes(tty2),
            [0xFA, 0xFB, 0x07, 0x2A, 0x2B, 0x02, 0x68, 0x69, 0x2C, 0xFA]
        );
        // ARIA's form with a trailing NUL decodes to the same string.
        assert_eq!(
            Arg::decode(&[0x2B, 0x02, 0x68, 0x69, 0x00]),
            Ok(Arg::Str(b"hi".to_vec()))
        );
    }

    #[test]
    fn out_of_range_values_are_clamped_not_sent_raw() {
        // VEL 5000 → 2200 = 0x0898: checksum 0x0B3B + 0x9808 = 0xA343.
        assert_eq!(
            bytes(Command::Vel(5000)),
            [0xFA, 0xFB, 0x06, 0x0B, 0x3B, 0x98, 0x08, 0xA3, 0x43]
        );
        assert_eq!(
            Command::Rvel(-900).number_and_arg(&CommandLimits::P3DX),
            (number::RVEL, Arg::Int(-500))
        );
        assert_eq!(
            Command::Head(-90).number_and_arg(&CommandLimits::P3DX),
            (number::HEAD, Arg::Int(270))
        );
        assert_eq!(
            Command::SetV(-5).number_and_arg(&CommandLimits::P3DX),
            (number::SETV, Arg::Int(0))
        );
        assert_eq!(to_i16_clamped("x", 1e9), i16::MAX);
        assert_eq!(to_i16_clamped("x", f64::NAN), 0);
        assert_eq!(vel2_units("x", 5000.0, 20.0), 127);
        assert_eq!(vel2_units("x", -210.0, 20.0), -11);
    }

    #[test]
    fn decode_depends_on_phase() {
        let f = Frame::new(0, vec![]);
        assert_eq!(
            Command::from_frame(&f, LinkPhase::Handshake),
            Ok(Command::Sync0)
        );
        assert_eq!(Command::from_frame(&f, LinkPhase::Open), Ok(Command::Pulse));
        // ARIA sends OPEN/CLOSE with an int argument.
        let f = Frame::new(2, vec![0x3B, 0x01, 0x00]);
        assert_eq!(Command::from_frame(&f, LinkPhase::Open), Ok(Command::Close));
    }

    #[test]
    fn malformed_arguments_are_errors() {
        let f = Frame::new(number::VEL, vec![0x3B, 0x01]);
        assert!(matches!(
            Command::from_frame(&f, LinkPhase::Open),
            Err(CommandError::Arg {
                source: ArgError::Truncated { .. },
                ..
            })
        ));
        let f = Frame::new(number::VEL, vec![0x77, 0x01, 0x00]);
        assert!(matches!(
            Command::from_frame(&f, LinkPhase::Open),
            Err(CommandError::Arg {
                source: ArgError::UnknownType { ty: 0x77, .. },
                ..
            })
        ));
        let f = Frame::new(number::VEL, vec![]);
        assert!(matches!(
            Command::from_frame(&f, LinkPhase::Open),
            Err(CommandError::NeedsInt { .. })
        ));
        assert_eq!(
            Arg::Int(70000).encode(),
            Err(ArgError::IntOutOfRange(70000))
        );
        let long = Command::Other {
            number: 42,
            arg: Arg::Str(vec![b'a'; 251]),
        };
        assert!(matches!(
            long.encode(&CommandLimits::P3DX),
            Err(ArgError::Frame(_))
        ));
    }
}

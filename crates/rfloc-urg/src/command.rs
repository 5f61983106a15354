//! Host → sensor commands of SCIP 2.0 that rfloc sends (each a line ending in LF).

/// One command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// `BM`: switch the laser on (measurement starts).
    BeamOn,
    /// `QT`: switch the laser off (measurement stops).
    Quit,
    /// `GD`: the latest scan from `start` to `end` step, `cluster` adjacent steps merged into
    /// one value (the smallest), three characters per value.
    GetDistance { start: u16, end: u16, cluster: u8 },
    /// `SCIP2.0`: switch a SCIP 1.1 sensor to SCIP 2.0 (status `0E` from one already there).
    Scip2,
    /// `VV`: vendor, product, firmware, protocol and serial number.
    Version,
    /// `PP`: model, range limits, step geometry and motor speed.
    Parameters,
    /// `II`: model, laser, motor and link state, time.
    State,
}

impl Command {
    /// The command line as sent, with its line feed; `GD` fields are zero-padded decimals
    /// (`GD0044072501` = steps 44 to 725, cluster 1).
    #[must_use]
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut line = self.echo();
        line.push(b'\n');
        line
    }

    /// What the sensor echoes back as the first line of its reply.
    #[must_use]
    pub fn echo(&self) -> Vec<u8> {
        match self {
            Command::BeamOn => b"BM".to_vec(),
            Command::Quit => b"QT".to_vec(),
            Command::GetDistance {
                start,
                end,
                cluster,
            } => format!(
                "GD{:04}{:04}{:02}",
                start % 10_000,
                end % 10_000,
                cluster % 100
            )
            .into_bytes(),
            Command::Scip2 => b"SCIP2.0".to_vec(),
            Command::Version => b"VV".to_vec(),
            Command::Parameters => b"PP".to_vec(),
            Command::State => b"II".to_vec(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_are_lines() {
        assert_eq!(Command::BeamOn.to_bytes(), b"BM\n");
        assert_eq!(Command::Quit.to_bytes(), b"QT\n");
        let gd = Command::GetDistance {
            start: 44,
            end: 725,
            cluster: 1,
        };
        assert_eq!(gd.to_bytes(), b"GD0044072501\n");
        assert_eq!(Command::Scip2.to_bytes(), b"SCIP2.0\n");
        assert_eq!(Command::Parameters.to_bytes(), b"PP\n");
        assert_eq!(Command::Version.to_bytes(), b"VV\n");
        assert_eq!(Command::State.to_bytes(), b"II\n");
    }
}

//! `TagListCustomFormat`: compiling the format string into a template and matching tag lines.
//!
//! The reader substitutes `%x` and `${NAME}` tokens and copies everything else literally
//! (protocols/alien-alr9900.md §3.5). A line is matched literal by literal: each field's value
//! runs up to the first occurrence of the literal that follows it, so a format is unambiguous
//! when every field is followed by a literal that cannot occur in the field's value. The
//! compiler rejects two fields with no literal between them, and a spaced tag ID (`%i`)
//! followed by a literal made only of hex digits and spaces.

/// What a token means.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FieldKind {
    /// `%i`, `${TAGIDW}`: hex ID in space-separated groups.
    TagIdSpaced,
    /// `%k`, `${TAGID}`, `${TAGIDB}`: hex ID.
    TagId,
    /// `%m`, `${RSSI}`.
    Rssi,
    /// `%r`, `${COUNT}`.
    Count,
    /// `%a`, `${TX}`: antenna.
    Antenna,
    /// `%d`, `${DATE1}`.
    DiscoveryDate,
    /// `%t`, `${TIME1}`.
    DiscoveryTime,
    /// `%D`, `${DATE2}`.
    LastDate,
    /// `%T`, `${TIME2}`.
    LastTime,
    /// `${MSEC1}`.
    DiscoveryMillis,
    /// `${MSEC2}`.
    LastMillis,
    /// `%p`, `%P`, `${PROTO}`, `${PROTO#}`.
    Protocol,
    /// Any other token: matched and ignored.
    Other,
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum Piece {
    Literal(String),
    Field(FieldKind),
}

/// A bad custom format.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CustomFormatError {
    #[error("custom format {0:?} has two fields with no literal between them")]
    AdjacentFields(String),
    #[error("custom format {0:?}: the literal after %i can occur inside a spaced tag ID")]
    AmbiguousTagId(String),
    #[error("custom format {0:?} has no tag ID field")]
    NoTagId(String),
    #[error("unterminated ${{…}} in custom format {0:?}")]
    Unterminated(String),
}

/// A compiled `TagListCustomFormat`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CustomFormat {
    source: String,
    pieces: Vec<Piece>,
}

fn percent_kind(c: char) -> FieldKind {
    match c {
        'i' => FieldKind::TagIdSpaced,
        'k' => FieldKind::TagId,
        'm' => FieldKind::Rssi,
        'r' => FieldKind::Count,
        'a' => FieldKind::Antenna,
        'd' => FieldKind::DiscoveryDate,
        't' => FieldKind::DiscoveryTime,
        'D' => FieldKind::LastDate,
        'T' => FieldKind::LastTime,
        'p' | 'P' => FieldKind::Protocol,
        _ => FieldKind::Other,
    }
}

fn dollar_kind(name: &str) -> FieldKind {
    match name.to_ascii_uppercase().as_str() {
        "TAGID" | "TAGIDB" => FieldKind::TagId,
        "TAGIDW" => FieldKind::TagIdSpaced,
        "RSSI" => FieldKind::Rssi,
        "COUNT" => FieldKind::Count,
        "TX" => FieldKind::Antenna,
        "DATE1" => FieldKind::DiscoveryDate,
        "TIME1" => FieldKind::DiscoveryTime,
        "DATE2" => FieldKind::LastDate,
        "TIME2" => FieldKind::LastTime,
        "MSEC1" => FieldKind::DiscoveryMillis,
        "MSEC2" => FieldKind::LastMillis,
        "PROTO" | "PROTO#" => FieldKind::Protocol,
        _ => FieldKind::Other,
    }
}

impl CustomFormat {
    /// Compiles a format string.
    ///
    /// # Errors
    /// [`CustomFormatError`] when the format cannot be matched unambiguously.
    pub fn compile(format: &str) -> Result<Self, CustomFormatError> {
        let mut pieces = Vec::new();
        let mut lit = String::new();
        let mut chars = format.chars().peekable();
        let push_field = |pieces: &mut Vec<Piece>, lit: &mut String, k| {
            if !lit.is_empty() {
                pieces.push(Piece::Literal(std::mem::take(lit)));
            }
            pieces.push(Piece::Field(k));
        };
        while let Some(c) = chars.next() {
            match c {
                '%' => match chars.next() {
                    Some('%') => lit.push('%'),
                    Some(t) => push_field(&mut pieces, &mut lit, percent_kind(t)),
                    None => lit.push('%'),
                },
                '$' if chars.peek() == Some(&'{') => {
                    chars.next();
                    let mut name = String::new();
                    loop {
                        match chars.next() {
                            Some('}') => break,
                            Some(ch) => name.push(ch),
                            None => return Err(CustomFormatError::Unterminated(format.into())),
                        }
                    }
                    push_field(&mut pieces, &mut lit, dollar_kind(&name));
                }
                _ => lit.push(c),
            }
        }
        if !lit.is_empty() {
            pieces.push(Piece::Literal(lit));
        }
        for pair in pieces.windows(2) {
            match pair {
                [Piece::Field(_), Piece::Field(_)] => {
                    return Err(CustomFormatError::AdjacentFields(format.into()))
                }
                [Piece::Field(FieldKind::TagIdSpaced), Piece::Literal(l)]
                    if l.chars().all(|c| c.is_ascii_hexdigit() || c == ' ') =>
                {
                    return Err(CustomFormatError::AmbiguousTagId(format.into()))
                }
                _ => {}
            }
        }
        if !pieces
            .iter()
            .any(|p| matches!(p, Piece::Field(FieldKind::TagId | FieldKind::TagIdSpaced)))
        {
            return Err(CustomFormatError::NoTagId(format.into()));
        }
        Ok(Self {
            source: format.to_string(),
            pieces,
        })
    }

    /// The format string.
    #[must_use]
    pub fn source(&self) -> &str {
        &self.source
    }

    /// Matches one line; returns each field's raw text, or `None` if the line does not fit.
    #[must_use]
    pub fn match_line<'a>(&self, line: &'a str) -> Option<Vec<(FieldKind, &'a str)>> {
        let mut rest = line.trim_end_matches(['\r', '\n']);
        let mut out = Vec::new();
        let mut iter = self.pieces.iter().peekable();
        while let Some(piece) = iter.next() {
            match piece {
                Piece::Literal(l) => {
                    // Leading spaces of the first literal are tolerated (reader padding).
                    rest = rest.strip_prefix(l.as_str()).or_else(|| {
                        if out.is_empty() {
                            rest.trim_start().strip_prefix(l.trim_start())
                        } else {
                            None
                        }
                    })?;
                }
                Piece::Field(kind) => {
                    let end = match iter.peek() {
                        Some(Piece::Literal(next)) => rest.find(next.as_str())?,
                        _ => rest.len(),
                    };
                    let (value, tail) = rest.split_at(end);
                    out.push((*kind, value.trim()));
                    rest = tail;
                }
            }
        }
        if rest.trim().is_empty() {
            Some(out)
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seed000_format() {
        // Seed 000 appendix "Scan Visible Tags Function": `IDK %i RSSI %m TIME %t;`.
        let f = CustomFormat::compile("IDK %i RSSI %m TIME %t;").unwrap();
        let m = f
            .match_line("IDK 47EC EDCE 4236 1F36 603B CB80 RSSI 2235.3 TIME 10:00:05;")
            .unwrap();
        assert_eq!(
            m,
            vec![
                (FieldKind::TagIdSpaced, "47EC EDCE 4236 1F36 603B CB80"),
                (FieldKind::Rssi, "2235.3"),
                (FieldKind::DiscoveryTime, "10:00:05"),
            ]
        );
        assert!(f.match_line("Tag:0102 0304, Disc:…").is_none());
    }

    #[test]
    fn reference_custom_formats() {
        // §3.5 [MAXBL4] vector.
        let f = CustomFormat::compile("%k;${MSEC1};${MSEC2};%a;%m;%r").unwrap();
        let m = f
            .match_line("E20000165919007818405C7B;1518784324007;1518784353958;0;-40.3;908")
            .unwrap();
        assert_eq!(m[0], (FieldKind::TagId, "E20000165919007818405C7B"));
        assert_eq!(m[4], (FieldKind::Rssi, "-40.3"));
        assert_eq!(m[5], (FieldKind::Count, "908"));
        // §3.5 [KQ] ALR-9900+EMA vector.
        let f = CustomFormat::compile(
            "id:%k t:${MSEC2} TIME2:${TIME2} a:%a vel:${SPEED} sig:${RSSI} freq:${FREQ}",
        )
        .unwrap();
        let m = f
            .match_line("id:E2003009281101450600D744 t:1790993096903 TIME2:19:04:56.903 a:2 vel:0.001 sig:11969.3 freq:865.700")
            .unwrap();
        assert_eq!(m[2], (FieldKind::LastTime, "19:04:56.903"));
        assert_eq!(m[5], (FieldKind::Rssi, "11969.3"));
        // §3.5 [G05]: `Tag %k, read %r times from antenna %a`.
        let f = CustomFormat::compile("Tag %k, read %r times from antenna %a").unwrap();
        let m = f
            .match_line("Tag 8000000000000808, read 3 times from antenna 0")
            .unwrap();
        assert_eq!(
            m,
            vec![
                (FieldKind::TagId, "8000000000000808"),
                (FieldKind::Count, "3"),
                (FieldKind::Antenna, "0")
            ]
        );
    }

    #[test]
    fn ambiguous_formats_are_rejected() {
        assert!(matches!(
            CustomFormat::compile("%k%m"),
            Err(CustomFormatError::AdjacentFields(_))
        ));
        assert!(matches!(
            CustomFormat::compile("%i %m"),
            Err(CustomFormatError::AmbiguousTagId(_))
        ));
        assert!(matches!(
            CustomFormat::compile("%m;%r"),
            Err(CustomFormatError::NoTagId(_))
        ));
        assert!(matches!(
            CustomFormat::compile("%k;${RSSI"),
            Err(CustomFormatError::Unterminated(_))
        ));
    }
}

//! TagList replies in the Text, Terse, XML and Custom formats.

use crate::custom_format::{CustomFormat, FieldKind};
use crate::reader_time::ReaderTime;

/// A tag ID (EPC or other), any even number of hex digits, stored as bytes.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
pub struct TagId(pub Vec<u8>);

impl std::fmt::Display for TagId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for b in &self.0 {
            write!(f, "{b:02X}")?;
        }
        Ok(())
    }
}

/// Parses a hex tag ID, ignoring spaces (`8000 00FE 8010 2AB7` or `800000FE80102AB7`).
#[must_use]
pub fn parse_tag_id(text: &str) -> Option<TagId> {
    let digits: Vec<u8> = text.bytes().filter(|b| *b != b' ').collect();
    if digits.is_empty() || !digits.len().is_multiple_of(2) {
        return None;
    }
    digits
        .chunks(2)
        .map(|p| {
            std::str::from_utf8(p)
                .ok()
                .and_then(|s| u8::from_str_radix(s, 16).ok())
        })
        .collect::<Option<Vec<u8>>>()
        .map(TagId)
}

/// One tag of a TagList.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TagRead {
    pub id: TagId,
    /// RSSI as printed (`%m`/`${RSSI}`); its meaning depends on the reader model.
    pub rssi: Option<f64>,
    pub count: Option<u32>,
    pub antenna: Option<u32>,
    pub discovered: Option<ReaderTime>,
    pub last_seen: Option<ReaderTime>,
    pub protocol: Option<String>,
}

impl TagRead {
    fn new(id: TagId) -> Self {
        Self {
            id,
            rssi: None,
            count: None,
            antenna: None,
            discovered: None,
            last_seen: None,
            protocol: None,
        }
    }
}

/// A TagList line that could not be parsed, with the reason.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error, serde::Serialize)]
#[error("malformed tag line {line:?}: {reason}")]
pub struct MalformedTagLine {
    pub line: String,
    pub reason: String,
}

/// The reader's `TagListFormat`, with the compiled custom format for `Custom`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TagListFormat {
    Text,
    Terse,
    Xml,
    Custom(CustomFormat),
}

fn bad(line: &str, reason: impl Into<String>) -> MalformedTagLine {
    MalformedTagLine {
        line: line.to_string(),
        reason: reason.into(),
    }
}

fn is_no_tags(line: &str) -> bool {
    line.trim().eq_ignore_ascii_case("(No Tags)")
}

impl TagListFormat {
    /// Parses a TagList reply body. `(No Tags)` and blank lines give nothing. A line that does
    /// not fit is returned as malformed (and logged); the other lines still parse. For
    /// `Custom`, a line that does not fit the template but fits the Text format is accepted
    /// (firmware that ignores the custom format, reference §6 item 7).
    #[must_use]
    pub fn parse(&self, body: &str) -> (Vec<TagRead>, Vec<MalformedTagLine>) {
        if let TagListFormat::Xml = self {
            return parse_xml(body);
        }
        let mut tags = Vec::new();
        let mut bad_lines = Vec::new();
        for line in body
            .split(['\r', '\n'])
            .map(str::trim)
            .filter(|l| !l.is_empty())
        {
            if is_no_tags(line) {
                continue;
            }
            let r = match self {
                TagListFormat::Text => parse_text_line(line),
                TagListFormat::Terse => parse_terse_line(line),
                TagListFormat::Custom(f) => {
                    parse_custom_line(f, line).or_else(|e| parse_text_line(line).map_err(|_| e))
                }
                TagListFormat::Xml => Err(bad(line, "unreachable")),
            };
            match r {
                Ok(t) => tags.push(t),
                Err(e) => {
                    tracing::warn!(%e, "alien: dropped tag line");
                    bad_lines.push(e);
                }
            }
        }
        (tags, bad_lines)
    }

    /// The value for `set TagListFormat` (`Text`, `Terse`, `XML`, `Custom`).
    #[must_use]
    pub fn setting_name(&self) -> &'static str {
        match self {
            TagListFormat::Text => "Text",
            TagListFormat::Terse => "Terse",
            TagListFormat::Xml => "XML",
            TagListFormat::Custom(_) => "Custom",
        }
    }
}

fn parse_num<T: std::str::FromStr>(line: &str, what: &str, v: &str) -> Result<T, MalformedTagLine> {
    v.trim()
        .parse()
        .map_err(|_| bad(line, format!("bad {what} {v:?}")))
}

/// Text format (§3.2): `Tag:<id>, Disc:<date time>, Last:<date time>, Count:n, Ant:n[, Proto:n]`.
/// Key-based: fields split on `,`, each on its first `:`; unknown keys ignored.
fn parse_text_line(line: &str) -> Result<TagRead, MalformedTagLine> {
    let mut tag: Option<TagRead> = None;
    let mut rest = Vec::new();
    for field in line.split(',') {
        let Some((k, v)) = field.split_once(':') else {
            return Err(bad(line, format!("field {field:?} has no ':'")));
        };
        let (k, v) = (k.trim(), v.trim());
        if k.eq_ignore_ascii_case("Tag") {
            let id = parse_tag_id(v).ok_or_else(|| bad(line, format!("bad tag ID {v:?}")))?;
            tag = Some(TagRead::new(id));
        } else {
            rest.push((k, v));
        }
    }
    let mut t = tag.ok_or_else(|| bad(line, "no Tag: field"))?;
    for (k, v) in rest {
        match k.to_ascii_lowercase().as_str() {
            "disc" => t.discovered = ReaderTime::parse(v),
            "last" => t.last_seen = ReaderTime::parse(v),
            "count" => t.count = Some(parse_num(line, "count", v)?),
            "ant" => t.antenna = Some(parse_num(line, "antenna", v)?),
            "proto" => t.protocol = Some(v.to_string()),
            "rssi" => t.rssi = Some(parse_num(line, "RSSI", v)?),
            _ => {}
        }
    }
    Ok(t)
}

/// Terse format (§3.3, per the guide): `<id>,<count>,<antenna>`.
fn parse_terse_line(line: &str) -> Result<TagRead, MalformedTagLine> {
    let mut it = line.split(',').map(str::trim);
    let id = it
        .next()
        .and_then(parse_tag_id)
        .ok_or_else(|| bad(line, "bad tag ID"))?;
    let mut t = TagRead::new(id);
    t.count = Some(parse_num(line, "count", it.next().unwrap_or_default())?);
    t.antenna = Some(parse_num(line, "antenna", it.next().unwrap_or_default())?);
    if it.next().is_some() {
        return Err(bad(line, "more than three Terse fields"));
    }
    Ok(t)
}

fn parse_custom_line(f: &CustomFormat, line: &str) -> Result<TagRead, MalformedTagLine> {
    let fields = f
        .match_line(line)
        .ok_or_else(|| bad(line, format!("does not fit {:?}", f.source())))?;
    let mut t = TagRead::new(TagId(Vec::new()));
    let mut id = None;
    let (mut d1, mut t1, mut d2, mut t2) = (None, None, None, None);
    for (kind, v) in fields {
        match kind {
            FieldKind::TagId | FieldKind::TagIdSpaced => {
                id = Some(parse_tag_id(v).ok_or_else(|| bad(line, format!("bad tag ID {v:?}")))?);
            }
            FieldKind::Rssi => t.rssi = Some(parse_num(line, "RSSI", v)?),
            FieldKind::Count => t.count = Some(parse_num(line, "count", v)?),
            FieldKind::Antenna => t.antenna = Some(parse_num(line, "antenna", v)?),
            FieldKind::DiscoveryDate => d1 = ReaderTime::parse_date(v),
            FieldKind::DiscoveryTime => {
                t1 = Some(
                    ReaderTime::parse_time(v)
                        .ok_or_else(|| bad(line, format!("bad time {v:?}")))?,
                );
            }
            FieldKind::LastDate => d2 = ReaderTime::parse_date(v),
            FieldKind::LastTime => {
                t2 = Some(
                    ReaderTime::parse_time(v)
                        .ok_or_else(|| bad(line, format!("bad time {v:?}")))?,
                );
            }
            FieldKind::DiscoveryMillis => {
                t.discovered = Some(ReaderTime::EpochMillis(parse_num(line, "epoch ms", v)?));
            }
            FieldKind::LastMillis => {
                t.last_seen = Some(ReaderTime::EpochMillis(parse_num(line, "epoch ms", v)?));
            }
            FieldKind::Protocol => t.protocol = Some(v.to_string()),
            FieldKind::Other => {}
        }
    }
    t.id = id.ok_or_else(|| bad(line, "no tag ID"))?;
    if let Some(s) = t1 {
        t.discovered = Some(ReaderTime::Clock {
            date: d1,
            seconds_of_day: s,
        });
    }
    if let Some(s) = t2 {
        t.last_seen = Some(ReaderTime::Clock {
            date: d2,
            seconds_of_day: s,
        });
    }
    Ok(t)
}

/// The text of `<name>…</name>` inside `block` (element names case-insensitive).
fn element<'a>(block: &'a str, lower_block: &str, name: &str) -> Option<&'a str> {
    let open = format!("<{}>", name.to_ascii_lowercase());
    let close = format!("</{}>", name.to_ascii_lowercase());
    let start = lower_block.find(&open)? + open.len();
    let end = start + lower_block.get(start..)?.find(&close)?;
    block.get(start..end).map(str::trim)
}

/// XML format (§3.4): `<Alien-RFID-Tag>` blocks with `TagID`, `DiscoveryTime`,
/// `LastSeenTime`, `Antenna`, `ReadCount`, `Protocol`, optional `RSSI`; other elements ignored.
fn parse_xml(body: &str) -> (Vec<TagRead>, Vec<MalformedTagLine>) {
    let mut tags = Vec::new();
    let mut bad_blocks = Vec::new();
    let lower = body.to_ascii_lowercase();
    let open = "<alien-rfid-tag>";
    let close = "</alien-rfid-tag>";
    let mut pos = 0;
    while let Some(s) = lower.get(pos..).and_then(|r| r.find(open)) {
        let start = pos + s + open.len();
        let Some(e) = lower.get(start..).and_then(|r| r.find(close)) else {
            bad_blocks.push(bad(
                body.get(pos + s..).unwrap_or_default(),
                "unterminated <Alien-RFID-Tag>",
            ));
            break;
        };
        let end = start + e;
        pos = end + close.len();
        let (Some(block), Some(lblock)) = (body.get(start..end), lower.get(start..end)) else {
            break;
        };
        let r = (|| {
            let id = element(block, lblock, "TagID").ok_or_else(|| bad(block, "no <TagID>"))?;
            let mut t = TagRead::new(
                parse_tag_id(id).ok_or_else(|| bad(block, format!("bad tag ID {id:?}")))?,
            );
            t.discovered = element(block, lblock, "DiscoveryTime").and_then(ReaderTime::parse);
            t.last_seen = element(block, lblock, "LastSeenTime").and_then(ReaderTime::parse);
            if let Some(v) = element(block, lblock, "Antenna") {
                t.antenna = Some(parse_num(block, "antenna", v)?);
            }
            if let Some(v) = element(block, lblock, "ReadCount") {
                t.count = Some(parse_num(block, "count", v)?);
            }
            if let Some(v) = element(block, lblock, "RSSI") {
                t.rssi = Some(parse_num(block, "RSSI", v)?);
            }
            t.protocol = element(block, lblock, "Protocol").map(str::to_string);
            Ok::<_, MalformedTagLine>(t)
        })();
        match r {
            Ok(t) => tags.push(t),
            Err(e) => {
                tracing::warn!(%e, "alien: dropped XML tag");
                bad_blocks.push(e);
            }
        }
    }
    (tags, bad_blocks)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_format_reference_lines() {
        // §3.2: G05 example and the real ALR-9900 line with TagListMillis = ON.
        let (tags, bad) = TagListFormat::Text.parse(
            "Tag:1115 F268 81C3 C012, Disc:2003/01/21 09:00:51, Last:2003/01/21 09:00:51, Count:4, Ant:0\r\n\
             Tag:C033 1255 1023, Disc:2015/04/25 21:11:26.082, Last:2015/04/25 21:11:26.660, Count:8, Ant:0, Proto:2\r\n",
        );
        assert!(bad.is_empty());
        assert_eq!(tags[0].id.to_string(), "1115F26881C3C012");
        assert_eq!((tags[0].count, tags[0].antenna), (Some(4), Some(0)));
        assert_eq!(tags[1].id.0.len(), 6);
        assert_eq!(tags[1].protocol.as_deref(), Some("2"));
        assert_eq!(
            tags[1].last_seen,
            Some(ReaderTime::Clock {
                date: Some((2015, 4, 25)),
                seconds_of_day: 76286.66
            })
        );
    }

    #[test]
    fn terse_and_no_tags() {
        // §3.3 (guide order: ID, reads, antenna) and §3.1.
        let (tags, bad) =
            TagListFormat::Terse.parse("1115 F268 81C3 C012,4,0\r\n0100 0100 0002 0709,6,0\r\n");
        assert!(bad.is_empty());
        assert_eq!(tags[1].count, Some(6));
        let (tags, bad) = TagListFormat::Terse.parse("(No Tags)\r\n");
        assert!(tags.is_empty() && bad.is_empty());
        let (tags, bad) = TagListFormat::Text.parse("");
        assert!(tags.is_empty() && bad.is_empty());
    }

    #[test]
    fn xml_format_reference_block() {
        // §3.4 (G05 p.53–54), with a declaration and lower-case tags mixed in.
        let body = "<?xml version=\"1.0\"?>\r\n<Alien-RFID-Tag-List>\r\n<Alien-RFID-Tag>\r\n<TagID>3000 2141 60C0 0400 0000 6013</TagID>\r\n\
<DiscoveryTime>2005/05/31 17:39:13</DiscoveryTime>\r\n<LastSeenTime>2005/05/31 17:39:14</LastSeenTime>\r\n<Antenna>1</Antenna>\r\n\
<ReadCount>19</ReadCount>\r\n<Protocol>Class 1 Gen 2</Protocol>\r\n</Alien-RFID-Tag>\r\n<alien-rfid-tag><tagid>01 02</tagid><rssi>-40.5</rssi></alien-rfid-tag>\r\n</Alien-RFID-Tag-List>\r\n";
        let (tags, bad) = TagListFormat::Xml.parse(body);
        assert!(bad.is_empty(), "{bad:?}");
        assert_eq!(tags.len(), 2);
        assert_eq!(tags[0].id.to_string(), "3000214160C0040000006013");
        assert_eq!((tags[0].count, tags[0].antenna), (Some(19), Some(1)));
        assert_eq!(tags[0].protocol.as_deref(), Some("Class 1 Gen 2"));
        assert_eq!(tags[1].rssi, Some(-40.5));
    }

    #[test]
    fn malformed_lines_are_reported_not_fatal() {
        let (tags, bad) = TagListFormat::Text
            .parse("Tag:ZZ, Count:1\r\nTag:0102, Count:x\r\nTag:0102, Count:2\r\n");
        assert_eq!(tags.len(), 1);
        assert_eq!(bad.len(), 2);
        assert_eq!(bad[0].line, "Tag:ZZ, Count:1");
    }

    #[test]
    fn custom_falls_back_to_text() {
        let f = TagListFormat::Custom(CustomFormat::compile("IDK %i RSSI %m TIME %t;").unwrap());
        let (tags, bad) = f.parse("Tag:0102 0304, Disc:2003/01/21 09:00:51, Last:2003/01/21 09:00:51, Count:4, Ant:0\r\nIDK 0A0B RSSI x TIME 10:00:00;\r\n");
        assert_eq!(tags.len(), 1);
        assert_eq!(bad.len(), 1);
        assert!(bad[0].reason.contains("RSSI"));
    }
}

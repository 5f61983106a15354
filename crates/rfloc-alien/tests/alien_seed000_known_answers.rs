//! Known answers from seed 000 (`000_444784c69108b6aa.txt`), appendix "Scan Visible Tags
//! Function": its Matlab parser is positional. It takes the ID as 29 characters starting 2
//! after the first `K` (`dataLine(delimIDx(1)+2 : delimIDx(1)+2+28)`, spaces then removed) and
//! the RSSI from 34 after that `K` up to the character before the first `T`
//! (`dataLine(delimIDx(1)+2+28+6 : delimRSSx(1)-1)`, then `str2double`). That oracle is applied
//! to every tag line of the reference capture and compared with this crate's key-based parse.

use std::path::PathBuf;

use rfloc_alien::{CustomFormat, TagListFormat, SEED000_CUSTOM_FORMAT};
use rfloc_capture::{Capture, RecordKind};

/// The seed's extraction, 1-based Matlab indices turned into 0-based slices.
fn matlab_extract(line: &str) -> Option<(String, f64)> {
    let k = line.find('K')? + 1; // 1-based index of the first K
    let t = line.find('T')? + 1; // 1-based index of the first T
    let id: String = line
        .get(k + 1..k + 2 + 28)?
        .chars()
        .filter(|c| !c.is_whitespace())
        .collect();
    let rss: f64 = line.get(k + 2 + 28 + 6 - 1..t - 1)?.trim().parse().ok()?;
    Some((id, rss))
}

#[test]
fn key_based_parse_agrees_with_the_seed_matlab_parser() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/captures/alien-seed000-interactive/alien.cap");
    let cap = Capture::from_path(&path).unwrap();
    let fmt = TagListFormat::Custom(CustomFormat::compile(SEED000_CUSTOM_FORMAT).unwrap());
    let mut compared = 0;
    for rec in &cap.records {
        let RecordKind::Rx(bytes) = &rec.kind else {
            continue;
        };
        let text = String::from_utf8_lossy(bytes);
        for line in text.split("\r\n").filter(|l| l.starts_with("IDK ")) {
            let (want_id, want_rss) = matlab_extract(line).unwrap();
            let (tags, bad) = fmt.parse(line);
            assert!(bad.is_empty(), "{line}");
            assert_eq!(tags.len(), 1);
            assert_eq!(tags[0].id.to_string(), want_id, "{line}");
            assert_eq!(tags[0].rssi, Some(want_rss), "{line}");
            compared += 1;
        }
    }
    // 5 + 7 + 5 + 7 + 5 tag lines in the capture.
    assert_eq!(compared, 29);
}

/// The seed's parser assumes a 96-bit EPC (29 characters with spaces); a 64-bit EPC breaks it
/// (it would read into ` RSSI`), while the key-based parse still works.
#[test]
fn shorter_epc_breaks_the_positional_parser_but_not_this_one() {
    let line = "IDK 3000 2141 60C0 0400 RSSI 1950.3 TIME 10:00:06;";
    let (id, _) = matlab_extract(line).unwrap_or_default();
    assert_ne!(id, "3000214160C00400");
    let fmt = TagListFormat::Custom(CustomFormat::compile(SEED000_CUSTOM_FORMAT).unwrap());
    let (tags, bad) = fmt.parse(line);
    assert!(bad.is_empty());
    assert_eq!(tags[0].id.to_string(), "3000214160C00400");
    assert_eq!(tags[0].rssi, Some(1950.3));
}

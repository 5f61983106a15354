//! The HF floor's tag table: inline `[[estimator.tag]]` entries, a `uid,x,y` CSV file or a TOML
//! file of `[[tag]]` entries, or a built-in field asked for by name. There is no fallback: a
//! robot file without tags is a configuration error.

use std::path::Path;

use rfloc_hfgrid::TagGrid;
use serde::Deserialize;

use crate::config::{GridTag, HfGridSettings};

/// The built-in tag field called `name` (`seed002-test`: seed 002's nine test tags, the field
/// the simulator's HF reader emulates).
#[must_use]
pub fn builtin_tag_field(name: &str) -> Option<TagGrid> {
    (name == "seed002-test").then(TagGrid::seed002_test_field)
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct TagFile {
    #[serde(rename = "tag")]
    tags: Vec<GridTag>,
}

/// Reads a tag table file: CSV (`.csv`, a `uid,x,y` header, metres) or TOML (`[[tag]]` entries
/// with `uid`, `x`, `y`). Errors name the file and the row.
pub fn load_tag_map(path: &Path) -> Result<Vec<GridTag>, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read tag map {}: {e}", path.display()))?;
    let tags = if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"))
    {
        let mut reader = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .comment(Some(b'#'))
            .from_reader(text.as_bytes());
        let mut tags = Vec::new();
        for (i, row) in reader.deserialize::<GridTag>().enumerate() {
            let tag = row.map_err(|e| format!("{} row {}: {e}", path.display(), i + 2))?;
            tags.push(tag);
        }
        tags
    } else {
        toml::from_str::<TagFile>(&text)
            .map_err(|e| format!("{}: {}", path.display(), e.message()))?
            .tags
    };
    for t in &tags {
        if u64::from_str_radix(t.uid.trim(), 16).is_err() || t.uid.trim().len() > 16 {
            return Err(format!(
                "{}: {:?} is not a tag UID (16 hex digits)",
                path.display(),
                t.uid
            ));
        }
        if !(t.x.is_finite() && t.y.is_finite()) {
            return Err(format!(
                "{}: tag {} has no finite position",
                path.display(),
                t.uid
            ));
        }
    }
    if tags.is_empty() {
        return Err(format!("{} lists no tags", path.display()));
    }
    Ok(tags)
}

/// The tag grid of a configuration (`config_dir`: folder of the robot file, for `tag_map`).
pub fn tag_grid(settings: &HfGridSettings, config_dir: Option<&Path>) -> Result<TagGrid, String> {
    if let Some(name) = &settings.tag_field {
        return builtin_tag_field(name).ok_or_else(|| format!("no built-in tag field {name:?}"));
    }
    let mut tags = settings.tags.clone();
    if let Some(file) = &settings.tag_map {
        let path = config_dir.map_or_else(|| file.clone(), |d| d.join(file));
        tags.extend(load_tag_map(&path)?);
    }
    if tags.is_empty() {
        return Err("no tags: the floor's tag table is needed".into());
    }
    let mut grid = TagGrid::new(settings.pitch_m.max(0.01)).map_err(|e| e.to_string())?;
    for t in &tags {
        let uid = u64::from_str_radix(t.uid.trim(), 16)
            .map_err(|_| format!("{:?} is not a tag UID", t.uid))?;
        grid.insert(uid, t.x, t.y)
            .map_err(|e| format!("tag {}: {e}", t.uid))?;
    }
    Ok(grid)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn csv_and_toml_tag_maps_give_the_same_grid() {
        let dir = tempfile::tempdir().unwrap();
        let csv = dir.path().join("tags.csv");
        std::fs::write(
            &csv,
            "# floor A\nuid,x,y\nE00401503A5BD691, 0.1, 0.2\nE00401503A5BDAE4,0,0\n",
        )
        .unwrap();
        let toml = dir.path().join("tags.toml");
        std::fs::write(
            &toml,
            "[[tag]]\nuid = \"E00401503A5BD691\"\nx = 0.1\ny = 0.2\n[[tag]]\nuid = \"E00401503A5BDAE4\"\nx = 0.0\ny = 0.0\n",
        )
        .unwrap();
        let a = load_tag_map(&csv).unwrap();
        let b = load_tag_map(&toml).unwrap();
        assert_eq!(a, b);
        let settings = HfGridSettings {
            tag_map: Some("tags.csv".into()),
            ..HfGridSettings::default()
        };
        let grid = tag_grid(&settings, Some(dir.path())).unwrap();
        assert_eq!(grid.position(0xE004_0150_3A5B_D691), Some((0.1, 0.2)));
    }

    #[test]
    fn bad_rows_and_empty_tables_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let csv = dir.path().join("tags.csv");
        std::fs::write(&csv, "uid,x,y\nE00401503A5BD691,0.1,0.2\nnot-hex,0,0\n").unwrap();
        assert!(load_tag_map(&csv).unwrap_err().contains("not-hex"));
        std::fs::write(&csv, "uid,x,y\nE00401503A5BD691,0.1\n").unwrap();
        assert!(load_tag_map(&csv).unwrap_err().contains("row 2"));
        std::fs::write(&csv, "uid,x,y\n").unwrap();
        assert!(load_tag_map(&csv).unwrap_err().contains("no tags"));
        assert!(tag_grid(&HfGridSettings::default(), None).is_err());
        assert_eq!(
            tag_grid(
                &HfGridSettings {
                    tag_field: Some("seed002-test".into()),
                    ..HfGridSettings::default()
                },
                None
            )
            .unwrap()
            .len(),
            9
        );
    }
}

//! Configuration errors located by the TOML parser's spans.
//!
//! A robot file is parsed once into a [`DeTable`] whose keys and values carry their byte spans.
//! Sections are deserialized one by one from that tree, so one wrong key does not hide the
//! others, and semantic checks name a key path (`device[1].driver.api_mode`) that is resolved
//! to the key's span: every error reads `file:line:col: key …`.

use std::fmt;
use std::ops::Range;

use serde::de::DeserializeOwned;
use toml::de::{DeTable, DeValue, ValueDeserializer};
use toml::Spanned;

/// One configuration error: `file:line:col: key `a.b`: message`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConfigError {
    pub file: String,
    pub line: Option<usize>,
    pub column: Option<usize>,
    pub key: Option<String>,
    pub message: String,
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file)?;
        if let Some(l) = self.line {
            write!(f, ":{l}")?;
            if let Some(c) = self.column {
                write!(f, ":{c}")?;
            }
        }
        write!(f, ": ")?;
        if let Some(k) = &self.key {
            write!(f, "key `{k}`: ")?;
        }
        write!(f, "{}", self.message)
    }
}

impl std::error::Error for ConfigError {}

/// Every error found in one file, in file order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConfigErrors(pub Vec<ConfigError>);

impl ConfigErrors {
    /// The first error (there is always one).
    #[must_use]
    pub fn first(&self) -> Option<&ConfigError> {
        self.0.first()
    }
}

impl fmt::Display for ConfigErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, e) in self.0.iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            write!(f, "{e}")?;
        }
        Ok(())
    }
}

impl std::error::Error for ConfigErrors {}

/// A parsed TOML value with spans.
pub type Node<'i> = Spanned<DeValue<'i>>;

/// Collects errors of one file and locates them.
pub struct Diagnostics<'i> {
    file: String,
    text: &'i str,
    root: &'i Node<'i>,
    errors: Vec<(usize, ConfigError)>,
}

impl<'i> Diagnostics<'i> {
    pub(crate) fn new(file: &str, text: &'i str, root: &'i Node<'i>) -> Self {
        Self {
            file: file.to_string(),
            text,
            root,
            errors: Vec::new(),
        }
    }

    /// The root table.
    #[must_use]
    pub fn root(&self) -> &'i Node<'i> {
        self.root
    }

    /// 1-based line and column of a byte offset.
    fn line_col(&self, offset: usize) -> (usize, usize) {
        let before = self.text.get(..offset.min(self.text.len())).unwrap_or("");
        let line = before.matches('\n').count() + 1;
        let col = before.rfind('\n').map_or(before.chars().count(), |nl| {
            before.get(nl + 1..).map_or(0, |s| s.chars().count())
        }) + 1;
        (line, col)
    }

    /// An error at a byte span, naming `key`.
    pub fn at_span(&mut self, span: Option<Range<usize>>, key: Option<String>, message: String) {
        let (line, column, offset) = match span {
            Some(s) => {
                let (l, c) = self.line_col(s.start);
                (Some(l), Some(c), s.start)
            }
            None => (None, None, usize::MAX),
        };
        self.errors.push((
            offset,
            ConfigError {
                file: self.file.clone(),
                line,
                column,
                key,
                message,
            },
        ));
    }

    /// An error about the key at `path` (`device[1].driver.api_mode`). A key that is not in the
    /// file (a default was used) is located at the nearest table that is.
    pub fn error(&mut self, path: &str, message: impl Into<String>) {
        let span = locate(self.root, path);
        self.at_span(span, Some(path.to_string()), message.into());
    }

    /// Deserializes `node` (the value at `path`) into `T`; a failure is recorded, located by the
    /// parser's span, and gives `None`.
    pub fn deserialize<T: DeserializeOwned>(&mut self, path: &str, node: &Node<'i>) -> Option<T> {
        match T::deserialize(ValueDeserializer::from(node.clone())) {
            Ok(v) => Some(v),
            Err(e) => {
                let span = e.span().or_else(|| Some(node.span()));
                let key = span
                    .as_ref()
                    .and_then(|s| key_at(node, path, s.start))
                    .unwrap_or_else(|| path.to_string());
                self.at_span(span, Some(key), e.message().trim().to_string());
                None
            }
        }
    }

    /// True when no error was recorded.
    #[must_use]
    pub fn is_clean(&self) -> bool {
        self.errors.is_empty()
    }

    /// How many errors were recorded.
    #[must_use]
    pub fn count(&self) -> usize {
        self.errors.len()
    }

    /// The errors in file order, or `Ok` when there are none.
    pub fn finish(mut self) -> Result<(), ConfigErrors> {
        if self.errors.is_empty() {
            return Ok(());
        }
        self.errors.sort_by_key(|(offset, _)| *offset);
        Err(ConfigErrors(
            self.errors.into_iter().map(|(_, e)| e).collect(),
        ))
    }
}

/// The entries of a table node.
pub(crate) fn table<'a, 'i>(node: &'a Node<'i>) -> Option<&'a DeTable<'i>> {
    match node.get_ref() {
        DeValue::Table(t) => Some(t),
        _ => None,
    }
}

/// The value of `key` in a table node.
pub(crate) fn get<'a, 'i>(node: &'a Node<'i>, key: &str) -> Option<&'a Node<'i>> {
    table(node)?
        .iter()
        .find(|(k, _)| k.get_ref().as_ref() == key)
        .map(|(_, v)| v)
}

/// A table node without `key` (a tag such as `kind` or `pipeline` that selects the type).
pub(crate) fn without<'i>(node: &Node<'i>, key: &str) -> Node<'i> {
    match node.get_ref() {
        DeValue::Table(t) => {
            let rest: DeTable<'i> = t
                .iter()
                .filter(|(k, _)| k.get_ref().as_ref() != key)
                .map(|(k, v)| (k.clone(), v.clone()))
                .collect();
            Spanned::new(node.span(), DeValue::Table(rest))
        }
        other => Spanned::new(node.span(), other.clone()),
    }
}

/// A string value.
pub(crate) fn string<'a>(node: &'a Node<'_>) -> Option<&'a str> {
    match node.get_ref() {
        DeValue::String(s) => Some(s.as_ref()),
        _ => None,
    }
}

/// The key span of `key` in a table node (where its line starts), else its value span.
fn key_span(node: &Node<'_>, key: &str) -> Option<Range<usize>> {
    table(node)?
        .iter()
        .find(|(k, _)| k.get_ref().as_ref() == key)
        .map(|(k, _)| k.span())
}

/// One step of a key path: a key and an optional array index.
fn segments(path: &str) -> Vec<(&str, Option<usize>)> {
    path.split('.')
        .map(|seg| match seg.split_once('[') {
            Some((name, rest)) => (name, rest.trim_end_matches(']').parse().ok()),
            None => (seg, None),
        })
        .collect()
}

/// The span of the key at `path`, or of the deepest table on the way that exists.
pub(crate) fn locate(root: &Node<'_>, path: &str) -> Option<Range<usize>> {
    let mut node = root;
    let mut best: Option<Range<usize>> = None;
    for (name, index) in segments(path) {
        let Some(span) = key_span(node, name) else {
            return best;
        };
        let Some(value) = get(node, name) else {
            return Some(span);
        };
        best = Some(span);
        node = value;
        if let Some(i) = index {
            match node.get_ref() {
                DeValue::Array(items) => match items.get(i) {
                    Some(item) => {
                        best = Some(item.span());
                        node = item;
                    }
                    None => return best,
                },
                _ => return best,
            }
        }
    }
    best
}

/// The path of the key whose name or value starts at (or contains) `offset` inside `node`.
fn key_at(node: &Node<'_>, path: &str, offset: usize) -> Option<String> {
    let t = table(node)?;
    for (k, v) in t {
        let name = k.get_ref().as_ref();
        let full = if path.is_empty() {
            name.to_string()
        } else {
            format!("{path}.{name}")
        };
        if k.span().contains(&offset) || k.span().start == offset {
            return Some(full);
        }
        if v.span().contains(&offset) {
            return match v.get_ref() {
                DeValue::Table(_) => key_at(v, &full, offset).or(Some(full)),
                DeValue::Array(items) => {
                    for (i, item) in items.iter().enumerate() {
                        if item.span().contains(&offset) {
                            let indexed = format!("{full}[{i}]");
                            return key_at(item, &indexed, offset).or(Some(indexed));
                        }
                    }
                    Some(full)
                }
                _ => Some(full),
            };
        }
    }
    None
}

/// Range checks of numbers the daemon turns into durations, counts and sizes, as
/// `key: must be …` errors under a key prefix.
pub struct Checks<'d, 'i> {
    diag: &'d mut Diagnostics<'i>,
    prefix: String,
}

impl<'d, 'i> Checks<'d, 'i> {
    /// Checks of keys under `prefix` (`device[1].driver`).
    pub fn new(diag: &'d mut Diagnostics<'i>, prefix: impl Into<String>) -> Self {
        Self {
            diag,
            prefix: prefix.into(),
        }
    }

    fn path(&self, key: &str) -> String {
        if self.prefix.is_empty() {
            key.to_string()
        } else if key.is_empty() {
            self.prefix.clone()
        } else {
            format!("{}.{key}", self.prefix)
        }
    }

    /// An error about `key`.
    pub fn error(&mut self, key: &str, message: impl Into<String>) {
        let path = self.path(key);
        self.diag.error(&path, message);
    }

    /// A finite number in `[min, max]`.
    pub fn range(&mut self, key: &str, value: f64, min: f64, max: f64, unit: &str) {
        if !(value.is_finite() && value >= min && value <= max) {
            self.error(
                key,
                format!("must be a number from {min} to {max}{unit}, not {value}"),
            );
        }
    }

    /// A finite number in `(0, max]`.
    pub fn positive(&mut self, key: &str, value: f64, max: f64, unit: &str) {
        if !(value.is_finite() && value > 0.0 && value <= max) {
            self.error(
                key,
                format!("must be a positive number up to {max}{unit}, not {value}"),
            );
        }
    }

    /// A finite number (any sign).
    pub fn finite(&mut self, key: &str, value: f64) {
        if !value.is_finite() {
            self.error(key, format!("must be a finite number, not {value}"));
        }
    }

    /// A count in `[min, max]`.
    pub fn count(&mut self, key: &str, value: u64, min: u64, max: u64) {
        if !(min..=max).contains(&value) {
            self.error(key, format!("must be from {min} to {max}, not {value}"));
        }
    }

    /// One of the listed words.
    pub fn one_of(&mut self, key: &str, value: &str, allowed: &[&str]) {
        if !allowed.contains(&value) {
            self.error(
                key,
                format!("{value:?} is not one of {}", allowed.join(", ")),
            );
        }
    }

    /// Checks under a deeper prefix.
    pub fn nested(&mut self, key: &str) -> Checks<'_, 'i> {
        let prefix = self.path(key);
        Checks {
            diag: self.diag,
            prefix,
        }
    }
}

/// A `[section]` that a build of rfloc may or may not understand (`[simulation]` needs the lab).
pub trait SectionCheck: Sync {
    /// Its top-level key.
    fn section(&self) -> &'static str;
    /// Parses and checks it; errors go to `diag`.
    fn check<'i>(&self, node: &Node<'i>, diag: &mut Diagnostics<'i>, ctx: &SectionContext<'_>);
}

/// What a [`SectionCheck`] may look at besides its own section.
pub struct SectionContext<'a> {
    /// Folder of the robot file.
    pub dir: Option<&'a std::path::Path>,
    /// Whether files the section names must exist here.
    pub check_files: bool,
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn paths_resolve_to_key_spans_and_defaults_to_their_table() {
        let text = "[robot]\nname = \"r\"\n\n[[device]]\nname = \"a\"\n\n[[device]]\nname = \"b\"\n[device.driver]\nkind = \"xbee\"\napi_mode = 3\n";
        let root = DeTable::parse(text).unwrap();
        let root = Spanned::new(root.span(), DeValue::Table(root.into_inner()));
        let mut d = Diagnostics::new("f.toml", text, &root);
        d.error("device[1].driver.api_mode", "must be 1 or 2");
        d.error("device[1].driver.discovery_timeout_s", "bad");
        d.error("device[0].name", "dup");
        let errs = d.finish().unwrap_err();
        let lines: Vec<String> = errs.0.iter().map(ToString::to_string).collect();
        assert_eq!(lines[0], "f.toml:5:1: key `device[0].name`: dup");
        assert_eq!(
            lines[1],
            "f.toml:9:9: key `device[1].driver.discovery_timeout_s`: bad"
        );
        assert_eq!(
            lines[2],
            "f.toml:11:1: key `device[1].driver.api_mode`: must be 1 or 2"
        );
    }
}

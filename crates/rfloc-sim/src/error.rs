//! Errors of world and scenario loading, of the `truth.csv` reader and of the outputs.

use std::path::PathBuf;

/// Everything that can go wrong loading simulation inputs. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The TOML text did not parse or did not match the expected schema.
    #[error("{path}:{line}:{column}: {message} (at `{key}`)")]
    Toml {
        path: PathBuf,
        line: usize,
        column: usize,
        /// The key (or table header) on the offending line, as written in the file.
        key: String,
        message: String,
    },
    /// The file parsed but a value is out of range or inconsistent.
    #[error("{path}:{line}: invalid `{key}`: {message}")]
    Invalid {
        path: PathBuf,
        /// Line of the key in the file, 0 when it could not be located (e.g. a default).
        line: usize,
        key: String,
        message: String,
    },
    /// A plot could not be drawn.
    #[error("{path}: {source}")]
    Plot {
        path: PathBuf,
        #[source]
        source: crate::plot::PlotError,
    },
    /// A `truth.csv` line could not be parsed.
    #[error("{path}:{line}: {message}")]
    Csv {
        path: PathBuf,
        line: usize,
        message: String,
    },
}

/// 1-based (line, column) of a byte offset in `text`.
#[must_use]
pub fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(text.len());
    let before = text.get(..offset).unwrap_or(text);
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let column = before
        .get(line_start..)
        .map_or(1, |s| s.chars().count() + 1);
    (line, column)
}

/// The key written on 1-based `line` of `text`: the text before `=`, or a `[table]` header.
#[must_use]
pub fn key_on_line(text: &str, line: usize) -> String {
    let Some(l) = text.lines().nth(line.saturating_sub(1)) else {
        return String::new();
    };
    let l = l.trim();
    if l.starts_with('[') {
        return l.to_string();
    }
    l.split_once('=')
        .map_or_else(|| l.to_string(), |(k, _)| k.trim().to_string())
}

/// Converts a `toml` deserialisation error into [`SimError::Toml`] with line, column and key.
pub(crate) fn from_toml(path: &std::path::Path, text: &str, err: &toml::de::Error) -> SimError {
    let (line, column) = err.span().map_or((0, 0), |s| line_column(text, s.start));
    SimError::Toml {
        path: path.to_path_buf(),
        line,
        column,
        key: if line > 0 {
            key_on_line(text, line)
        } else {
            String::new()
        },
        message: err.message().trim().to_string(),
    }
}

/// Line on which the dotted `key` is written (from the parser's spans: `goal.x` is the `x` of
/// `[goal]`, not the first `x =` of the file), else where `key = …` or `[key]` first appears
/// (a key the spans do not find), 0 when absent.
pub(crate) fn find_key_line(text: &str, key: &str) -> usize {
    spanned_key_line(text, key).unwrap_or_else(|| first_key_line(text, key))
}

/// The line of the dotted `key`'s name, by walking the parsed tables with their spans.
fn spanned_key_line(text: &str, key: &str) -> Option<usize> {
    use toml::de::{DeTable, DeValue};
    let root = DeTable::parse(text).ok()?;
    let mut table: &DeTable<'_> = root.get_ref();
    let mut span = None;
    let mut parts = key.split('.').peekable();
    while let Some(part) = parts.next() {
        let (k, v) = table.iter().find(|(k, _)| k.get_ref().as_ref() == part)?;
        span = Some(k.span());
        if parts.peek().is_some() {
            match v.get_ref() {
                DeValue::Table(t) => table = t,
                _ => return None,
            }
        }
    }
    let start = span?.start;
    Some(text.get(..start)?.matches('\n').count() + 1)
}

/// Line on which `key = …` (or the header `[key]`) is first written, 0 when absent.
fn first_key_line(text: &str, key: &str) -> usize {
    let last = key.rsplit('.').next().unwrap_or(key);
    let mut fallback = 0;
    for (i, l) in text.lines().enumerate() {
        let t = l.trim_start();
        let header = format!("[{key}]");
        let header2 = format!("[[{key}]]");
        if t.starts_with(&header) || t.starts_with(&header2) {
            return i + 1;
        }
        if fallback == 0 {
            let found = t.split(['{', ',', '[']).any(|part| {
                part.trim_start()
                    .strip_prefix(last)
                    .is_some_and(|rest| rest.trim_start().starts_with('='))
            });
            if found {
                fallback = i + 1;
            }
        }
    }
    fallback
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offsets_map_to_one_based_line_and_column() {
        let t = "a = 1\nbb = 2\n";
        assert_eq!(line_column(t, 0), (1, 1));
        assert_eq!(line_column(t, 6), (2, 1));
        assert_eq!(line_column(t, 9), (2, 4));
        assert_eq!(key_on_line(t, 2), "bb");
    }

    #[test]
    fn key_lines_found_in_inline_tables_and_headers() {
        let t = "[area]\nmin = [0, 0]\n[uhf_tags]\nrandom = { count = 3, seed = 1 }\n";
        assert_eq!(find_key_line(t, "uhf_tags.random.seed"), 4);
        assert_eq!(find_key_line(t, "area"), 1);
        assert_eq!(find_key_line(t, "nothing"), 0);
    }
}

//! Which TagList format the reader is in, followed through the `set` commands of a session
//! (`TagListCustomFormat`, then `TagListFormat = Custom`, in either order). No I/O.

use crate::custom_format::{CustomFormat, CustomFormatError};
use crate::setup::split_set;
use crate::taglist::TagListFormat;

/// The reader's current TagList format as a session's commands leave it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FormatTracker {
    format: TagListFormat,
    /// The last custom format set, in force once `TagListFormat = Custom`.
    custom: Option<CustomFormat>,
}

impl Default for FormatTracker {
    fn default() -> Self {
        Self {
            format: TagListFormat::Text,
            custom: None,
        }
    }
}

impl FormatTracker {
    /// The format the reader prints TagLists in now.
    #[must_use]
    pub fn format(&self) -> &TagListFormat {
        &self.format
    }

    /// Forces the format (a reader already configured by someone else).
    pub fn set_format(&mut self, format: TagListFormat) {
        self.format = format;
    }

    /// Follows one command the reader accepted; commands other than the two format settings
    /// change nothing.
    ///
    /// # Errors
    /// A `TagListCustomFormat` that does not compile.
    pub fn observe(&mut self, command: &str) -> Result<(), CustomFormatError> {
        let Some((key, value)) = split_set(command) else {
            return Ok(());
        };
        if key.eq_ignore_ascii_case("TagListCustomFormat") {
            let f = CustomFormat::compile(value)?;
            if matches!(self.format, TagListFormat::Custom(_)) {
                self.format = TagListFormat::Custom(f.clone());
            }
            self.custom = Some(f);
        } else if key.eq_ignore_ascii_case("TagListFormat") {
            self.format = match value.to_ascii_lowercase().as_str() {
                "text" => TagListFormat::Text,
                "terse" => TagListFormat::Terse,
                "xml" => TagListFormat::Xml,
                "custom" => match &self.custom {
                    Some(f) => TagListFormat::Custom(f.clone()),
                    None => TagListFormat::Text,
                },
                _ => return Ok(()),
            };
        }
        Ok(())
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn custom_format_in_either_order() {
        let mut a = FormatTracker::default();
        a.observe("TagListCustomFormat = IDK %i RSSI %m;").unwrap();
        assert_eq!(a.format(), &TagListFormat::Text);
        a.observe("set TagListFormat = Custom").unwrap();
        assert!(matches!(a.format(), TagListFormat::Custom(_)));
        let mut b = FormatTracker::default();
        b.observe("TagListFormat=Custom").unwrap();
        assert_eq!(b.format(), &TagListFormat::Text);
        b.observe("TagListCustomFormat=IDK %i RSSI %m;").unwrap();
        b.observe("TagListFormat=Custom").unwrap();
        assert_eq!(a.format(), b.format());
        b.observe("TagListFormat = Terse").unwrap();
        assert_eq!(b.format(), &TagListFormat::Terse);
        b.observe("get TagListFormat").unwrap();
        assert_eq!(b.format(), &TagListFormat::Terse);
    }
}

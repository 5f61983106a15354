//! Reader text on its way into an error or a log line: credentials removed, control characters
//! made visible, length bounded.
//!
//! A reader that echoes what it is sent puts the password into its replies (`\x01<password>\r\n`
//! before `Error: Invalid …`). Every piece of reader text the client turns into an error goes
//! through [`Redactor::clean`] first, so that no `Display` or `Debug` of an error, and no log
//! line built from one, holds the password. Control characters are escaped so that a device's
//! bytes cannot move the cursor, change colours or start a new log line.

/// What a credential in reader text is replaced by.
pub(crate) const REDACTED: &str = "<redacted>";

/// What reader text becomes when a credential cannot be cut out of it cleanly.
const WITHHELD: &str = "<reader text withheld: it held a credential>";

/// Longest reader text kept in an error, in characters (longer text ends in `…`).
pub(crate) const MAX_ERROR_TEXT_CHARS: usize = 200;

/// Removes the credentials from reader text. Its `Debug` shows how many it holds, never them.
#[derive(Clone, Default)]
pub(crate) struct Redactor {
    secrets: Vec<String>,
}

impl std::fmt::Debug for Redactor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Redactor")
            .field("secrets", &self.secrets.len())
            .finish()
    }
}

impl Redactor {
    /// A redactor of the given secrets (empty ones are ignored).
    pub(crate) fn new<'a>(secrets: impl IntoIterator<Item = &'a str>) -> Self {
        let mut secrets: Vec<String> = secrets
            .into_iter()
            .filter(|s| !s.is_empty())
            .map(str::to_string)
            .collect();
        // Longest first, so that a secret inside another is not cut out of it first.
        secrets.sort_by_key(|s| std::cmp::Reverse(s.len()));
        Self { secrets }
    }

    /// `text` with every occurrence of a secret replaced by [`REDACTED`].
    pub(crate) fn redact(&self, text: &str) -> String {
        let mut out = text.to_string();
        for s in &self.secrets {
            if out.contains(s.as_str()) {
                out = out.replace(s.as_str(), REDACTED);
            }
        }
        out
    }

    /// True when `text`, or its `Debug` form (without the quotes), holds a secret.
    fn leaks(&self, text: &str) -> bool {
        let debug = format!("{text:?}");
        let escaped = debug
            .get(1..debug.len().saturating_sub(1))
            .unwrap_or_default();
        self.secrets
            .iter()
            .any(|s| text.contains(s.as_str()) || escaped.contains(s.as_str()))
    }

    /// Reader text fit for an error: secrets redacted, then made [`printable`] and bounded to
    /// [`MAX_ERROR_TEXT_CHARS`]. Should a secret still show (a replacement that joined with its
    /// neighbours into one, an escape that spelled one, or one that shows only in `Debug`), the
    /// text is withheld altogether (and is empty should the notice say so itself).
    pub(crate) fn clean(&self, text: &str) -> String {
        let out = printable(&self.redact(text), MAX_ERROR_TEXT_CHARS);
        if !self.leaks(&out) {
            out
        } else if !self.leaks(WITHHELD) {
            WITHHELD.to_string()
        } else {
            String::new()
        }
    }
}

/// Bidirectional-text controls and invisible format characters: they reorder or hide what a
/// terminal shows.
fn is_format_char(c: char) -> bool {
    matches!(
        c,
        '\u{200B}'..='\u{200F}' | '\u{202A}'..='\u{202E}' | '\u{2060}'..='\u{2069}' | '\u{FEFF}'
    )
}

/// `text` as one printable line of at most `max_chars` characters: surrounding whitespace
/// trimmed, every run of whitespace (CR, LF, tab, line separators) one space, other control and
/// format characters escaped as `\u{..}`, and `…` where it was cut.
#[must_use]
pub(crate) fn printable(text: &str, max_chars: usize) -> String {
    let mut out = String::new();
    let mut chars = 0usize;
    let mut pending_space = false;
    for c in text.trim().chars() {
        if c.is_whitespace() {
            pending_space = true;
            continue;
        }
        let piece: String = if c.is_control() || is_format_char(c) {
            c.escape_unicode().to_string()
        } else {
            c.to_string()
        };
        let needed = piece.chars().count() + usize::from(pending_space);
        if chars + needed > max_chars {
            out.push('…');
            return out;
        }
        if pending_space {
            out.push(' ');
            pending_space = false;
        }
        out.push_str(&piece);
        chars += needed;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn echoed_password_is_redacted_with_or_without_its_framing() {
        let r = Redactor::new(["hunter2"]);
        for raw in [
            "\x01hunter2\r\nError: Invalid username/password\r\n",
            "hunter2\nError: Invalid username/password",
            "hunter2Error: Invalid username/password",
            "\x01hunter2\r\n\x01hunter2\r\nError: Invalid username/password",
        ] {
            let out = r.clean(raw);
            assert!(!out.contains("hunter2"), "{out}");
            assert!(out.contains("<redacted>"), "{out}");
            assert!(out.ends_with("Error: Invalid username/password"), "{out}");
            assert!(!out.chars().any(char::is_control), "{out:?}");
        }
        assert_eq!(
            r.clean("\x01hunter2\r\nError: Invalid username/password\r\n"),
            "\\u{1}<redacted> Error: Invalid username/password"
        );
    }

    #[test]
    fn control_and_format_characters_are_escaped() {
        let r = Redactor::default();
        assert_eq!(
            r.clean("Error 1: \x1b[31mred\x07\r\n\tWARN forged\u{202E}txt\u{2028}x\r\n"),
            "Error 1: \\u{1b}[31mred\\u{7} WARN forged\\u{202e}txt x"
        );
    }

    #[test]
    fn long_text_is_cut() {
        assert_eq!(printable("abcdef", 4), "abcd…");
        assert_eq!(printable("ab  cdef", 4), "ab c…");
        assert_eq!(printable("abcd", 4), "abcd");
        assert_eq!(printable("\x1bxyz", 5), "…");
        let long = "x".repeat(10_000);
        assert_eq!(
            Redactor::default().clean(&long).chars().count(),
            MAX_ERROR_TEXT_CHARS + 1
        );
    }

    #[test]
    fn a_replacement_that_forms_the_secret_again_withholds_the_text() {
        // `<redacted>` followed by `a` spells the secret `>a` again.
        let r = Redactor::new([">a"]);
        assert_eq!(r.clean(">aa"), WITHHELD);
        // An escape that spells the secret.
        let r = Redactor::new(["\\u{7}"]);
        assert_eq!(r.clean("bell \x07"), WITHHELD);
        // A secret inside the notice itself: nothing is kept.
        let r = Redactor::new(["<"]);
        assert_eq!(r.clean("a<b"), "");
    }

    #[test]
    fn debug_shows_no_secret() {
        let r = Redactor::new(["hunter2", ""]);
        assert_eq!(format!("{r:?}"), "Redactor { secrets: 1 }");
    }

    proptest! {
        #![proptest_config(ProptestConfig {
            cases: 512,
            rng_seed: proptest::test_runner::RngSeed::Fixed(0xA11E_0001),
            ..ProptestConfig::default()
        })]

        /// Whatever surrounds it, a secret never survives `clean`, nor do control characters.
        #[test]
        fn clean_never_shows_the_secret(
            secret in "[ -~]{1,12}",
            before in proptest::collection::vec(any::<u8>(), 0..40),
            after in proptest::collection::vec(any::<u8>(), 0..40),
            copies in 1usize..4,
        ) {
            let r = Redactor::new([secret.as_str()]);
            let mut raw = before.clone();
            for _ in 0..copies {
                raw.push(0x01);
                raw.extend_from_slice(secret.as_bytes());
                raw.extend_from_slice(b"\r\n");
            }
            raw.extend_from_slice(&after);
            let text = String::from_utf8_lossy(&raw);
            let out = r.clean(&text);
            prop_assert!(!out.contains(secret.as_str()), "{:?} in {:?}", secret, out);
            let debug = format!("{out:?}");
            let escaped = &debug[1..debug.len() - 1];
            prop_assert!(!escaped.contains(secret.as_str()), "{:?} in {:?}", secret, debug);
            prop_assert!(!out.chars().any(char::is_control), "{:?}", out);
            prop_assert!(out.chars().count() <= MAX_ERROR_TEXT_CHARS + 1);
        }
    }
}

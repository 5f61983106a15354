//! The `# key: value` header of a capture.

/// Header fields. Known keys are parsed into fields; unknown keys are kept in `extra`.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Header {
    /// `device`: `alien-alr9900`, `kts-rfidm1356`, `xbee-api1`, `xbee-api2`, `pioneer-aria`,
    /// `stepper-gpio` (not validated: new devices may appear).
    pub device: Option<String>,
    /// `link`: `serial <baud> <8N1|…>` or `tcp <host:port>`.
    pub link: Option<String>,
    /// `started`: UTC time, RFC 3339 text as written.
    pub started: Option<String>,
    /// `note` lines, in order.
    pub notes: Vec<String>,
    /// Other `key: value` pairs, in order.
    pub extra: Vec<(String, String)>,
}

impl Header {
    /// A header for the given device and link description.
    #[must_use]
    pub fn new(device: impl Into<String>, link: impl Into<String>) -> Self {
        Self {
            device: Some(device.into()),
            link: Some(link.into()),
            ..Self::default()
        }
    }

    pub(crate) fn absorb(&mut self, key: &str, value: &str) {
        let value = value.to_string();
        match key {
            "device" => self.device = Some(value),
            "link" => self.link = Some(value),
            "started" => self.started = Some(value),
            "note" => self.notes.push(value),
            _ => self.extra.push((key.to_string(), value)),
        }
    }

    /// Header lines (without the magic line), each ending in `\n`.
    #[must_use]
    pub fn to_lines(&self) -> String {
        let mut s = String::new();
        if let Some(d) = &self.device {
            s.push_str(&format!("# device: {d}\n"));
        }
        if let Some(l) = &self.link {
            s.push_str(&format!("# link: {l}\n"));
        }
        if let Some(t) = &self.started {
            s.push_str(&format!("# started: {t}\n"));
        }
        for n in &self.notes {
            s.push_str(&format!("# note: {n}\n"));
        }
        for (k, v) in &self.extra {
            s.push_str(&format!("# {k}: {v}\n"));
        }
        s
    }
}

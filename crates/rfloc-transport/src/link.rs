//! Link configuration and the single place where links are opened.

use serde::{Deserialize, Serialize};

use crate::error::TransportError;
use crate::Transport;

/// Character size of a serial link.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum DataBits {
    #[serde(rename = "5")]
    Five,
    #[serde(rename = "6")]
    Six,
    #[serde(rename = "7")]
    Seven,
    #[default]
    #[serde(rename = "8")]
    Eight,
}

/// Parity of a serial link.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Parity {
    #[default]
    None,
    Odd,
    Even,
}

/// Stop bits of a serial link.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum StopBits {
    #[default]
    #[serde(rename = "1")]
    One,
    #[serde(rename = "2")]
    Two,
}

/// Flow control of a serial link.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum FlowControl {
    #[default]
    None,
    Software,
    Hardware,
}

fn default_connect_timeout() -> f64 {
    5.0
}

/// A serial link: device path and line settings. In TOML data/stop bits are strings (`"8"`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SerialLink {
    pub path: String,
    pub baud: u32,
    #[serde(default)]
    pub data_bits: DataBits,
    #[serde(default)]
    pub parity: Parity,
    #[serde(default)]
    pub stop_bits: StopBits,
    #[serde(default)]
    pub flow_control: FlowControl,
}

/// A TCP link.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TcpLink {
    /// `host:port`.
    pub address: String,
    /// Seconds to wait for the connection.
    #[serde(default = "default_connect_timeout")]
    pub connect_timeout: f64,
}

/// How to reach a device.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum LinkConfig {
    Serial(SerialLink),
    Tcp(TcpLink),
}

impl LinkConfig {
    /// The capture header's `link` text, e.g. `serial 115200 8N1` or `tcp 127.0.0.1:23`.
    #[must_use]
    pub fn describe(&self) -> String {
        match self {
            LinkConfig::Serial(s) => {
                let bits = match s.data_bits {
                    DataBits::Five => '5',
                    DataBits::Six => '6',
                    DataBits::Seven => '7',
                    DataBits::Eight => '8',
                };
                let parity = match s.parity {
                    Parity::None => 'N',
                    Parity::Odd => 'O',
                    Parity::Even => 'E',
                };
                let stop = match s.stop_bits {
                    StopBits::One => '1',
                    StopBits::Two => '2',
                };
                format!("serial {} {bits}{parity}{stop}", s.baud)
            }
            LinkConfig::Tcp(t) => format!("tcp {}", t.address),
        }
    }
}

/// Opens the link described by `config`. This is the only function in rfloc that opens a
/// device link.
pub async fn open(config: &LinkConfig) -> Result<Transport, TransportError> {
    match config {
        LinkConfig::Serial(s) => Ok(Box::new(crate::serial::open(s)?)),
        LinkConfig::Tcp(t) => Ok(Box::new(crate::tcp::connect(t).await?)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn serial_link_from_toml_with_defaults() {
        let cfg: LinkConfig =
            toml::from_str("kind = \"serial\"\npath = \"/dev/ttyUSB0\"\nbaud = 115200\n").unwrap();
        assert_eq!(cfg.describe(), "serial 115200 8N1");
        let cfg: LinkConfig = toml::from_str(
            "kind = \"serial\"\npath = \"/dev/ttyS1\"\nbaud = 9600\ndata_bits = \"7\"\nparity = \"even\"\nstop_bits = \"2\"\nflow_control = \"hardware\"\n",
        )
        .unwrap();
        assert_eq!(cfg.describe(), "serial 9600 7E2");
    }

    #[test]
    fn unknown_keys_are_rejected() {
        let err = toml::from_str::<LinkConfig>("kind = \"tcp\"\naddress = \"a:1\"\nbogus = 1\n")
            .unwrap_err();
        assert!(err.to_string().contains("bogus"), "{err}");
    }
}

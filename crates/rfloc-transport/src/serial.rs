//! Serial links (tokio-serial).

use tokio_serial::{SerialPortBuilderExt, SerialStream};

use crate::error::TransportError;
use crate::link::{DataBits, FlowControl, Parity, SerialLink, StopBits};

/// Opens a serial port with the configured line settings, exclusively.
pub fn open(link: &SerialLink) -> Result<SerialStream, TransportError> {
    let builder = tokio_serial::new(&link.path, link.baud)
        .data_bits(match link.data_bits {
            DataBits::Five => tokio_serial::DataBits::Five,
            DataBits::Six => tokio_serial::DataBits::Six,
            DataBits::Seven => tokio_serial::DataBits::Seven,
            DataBits::Eight => tokio_serial::DataBits::Eight,
        })
        .parity(match link.parity {
            Parity::None => tokio_serial::Parity::None,
            Parity::Odd => tokio_serial::Parity::Odd,
            Parity::Even => tokio_serial::Parity::Even,
        })
        .stop_bits(match link.stop_bits {
            StopBits::One => tokio_serial::StopBits::One,
            StopBits::Two => tokio_serial::StopBits::Two,
        })
        .flow_control(match link.flow_control {
            FlowControl::None => tokio_serial::FlowControl::None,
            FlowControl::Software => tokio_serial::FlowControl::Software,
            FlowControl::Hardware => tokio_serial::FlowControl::Hardware,
        });
    let mut port = builder
        .open_native_async()
        .map_err(|source| TransportError::Serial {
            path: link.path.clone(),
            source,
        })?;
    port.set_exclusive(true)
        .map_err(|source| TransportError::Serial {
            path: link.path.clone(),
            source,
        })?;
    tracing::debug!(path = %link.path, baud = link.baud, "serial port open");
    Ok(port)
}

//! Bounds-checked reading of big-endian fields from frame data.

use crate::address::{Address16, Address64};

/// Reads fields front to back; every read returns `None` instead of running past the end.
#[derive(Debug, Clone)]
pub(crate) struct FieldReader<'a> {
    rest: &'a [u8],
}

impl<'a> FieldReader<'a> {
    pub(crate) fn new(bytes: &'a [u8]) -> Self {
        Self { rest: bytes }
    }

    pub(crate) fn array<const N: usize>(&mut self) -> Option<[u8; N]> {
        let (head, tail) = self.rest.split_first_chunk::<N>()?;
        self.rest = tail;
        Some(*head)
    }

    pub(crate) fn u8(&mut self) -> Option<u8> {
        let (first, tail) = self.rest.split_first()?;
        self.rest = tail;
        Some(*first)
    }

    pub(crate) fn u16(&mut self) -> Option<u16> {
        self.array::<2>().map(u16::from_be_bytes)
    }

    pub(crate) fn u32(&mut self) -> Option<u32> {
        self.array::<4>().map(u32::from_be_bytes)
    }

    pub(crate) fn address64(&mut self) -> Option<Address64> {
        self.array::<8>().map(|b| Address64(u64::from_be_bytes(b)))
    }

    pub(crate) fn address16(&mut self) -> Option<Address16> {
        self.u16().map(Address16)
    }

    /// Bytes up to (not including) the first 0x00, consuming the 0x00.
    pub(crate) fn until_nul(&mut self) -> Option<&'a [u8]> {
        let pos = self.rest.iter().position(|b| *b == 0)?;
        let (head, tail) = self.rest.split_at_checked(pos)?;
        self.rest = tail.get(1..)?;
        Some(head)
    }

    pub(crate) fn remaining(&self) -> &'a [u8] {
        self.rest
    }

    pub(crate) fn take_rest(&mut self) -> &'a [u8] {
        std::mem::take(&mut self.rest)
    }
}

//! CDR (OMG Common Data Representation, version 1, little endian) as ROS 2 puts it on the wire
//! and in rosbag2: a 4-byte encapsulation header `00 01 00 00` (CDR_LE, no options), then the
//! fields in order, each primitive aligned to its own size counted from the end of the header.
//! Strings are a `uint32` length including the terminating NUL, the bytes and the NUL; sequences
//! a `uint32` count and the elements.

/// The encapsulation header of little-endian plain CDR.
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// A CDR message being written.
#[derive(Debug, Default)]
pub struct CdrWriter {
    buf: Vec<u8>,
}

impl CdrWriter {
    /// An empty writer; [`CdrWriter::start`] begins each message.
    pub fn new() -> CdrWriter {
        CdrWriter {
            buf: Vec::with_capacity(4096),
        }
    }

    /// Clears the buffer and writes the encapsulation header.
    pub fn start(&mut self) {
        self.buf.clear();
        self.buf.extend_from_slice(&CDR_LE_HEADER);
    }

    /// The message: header and body.
    pub fn bytes(&self) -> &[u8] {
        &self.buf
    }

    fn align(&mut self, n: usize) {
        let body = self.buf.len() - CDR_LE_HEADER.len();
        let pad = (n - body % n) % n;
        self.buf.resize(self.buf.len() + pad, 0);
    }

    /// `bool`.
    pub fn bool(&mut self, v: bool) {
        self.buf.push(u8::from(v));
    }

    /// `int32`.
    pub fn i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// `uint32`.
    pub fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// `float32`.
    pub fn f32(&mut self, v: f32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// `float64`.
    pub fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// `string`.
    pub fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    /// The length of a sequence; its elements follow.
    pub fn sequence_len(&mut self, n: usize) {
        self.u32(n as u32);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn primitives_are_aligned_to_their_size_from_the_end_of_the_header() {
        let mut w = CdrWriter::new();
        w.start();
        w.bool(true);
        w.f64(1.0);
        w.string("ab");
        w.f32(0.5);
        let b = w.bytes();
        assert_eq!(&b[..4], &CDR_LE_HEADER);
        assert_eq!(b[4], 1);
        assert_eq!(&b[5..12], &[0; 7], "padding up to offset 8 of the body");
        assert_eq!(&b[12..20], &1.0f64.to_le_bytes());
        assert_eq!(&b[20..24], &3u32.to_le_bytes(), "length with the NUL");
        assert_eq!(&b[24..27], b"ab\0");
        assert_eq!(b[27], 0, "padding up to offset 24 of the body");
        assert_eq!(&b[28..32], &0.5f32.to_le_bytes());
    }
}

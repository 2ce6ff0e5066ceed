//! CDR (XCDR1, little endian), the encoding of ROS 2 messages, for the bulk channels.

/// Serializer of plain CDR (the encoding of ROS 2 messages), little endian.
pub(super) struct CdrWriter<'a> {
    buf: &'a mut Vec<u8>,
}

impl<'a> CdrWriter<'a> {
    pub(super) fn new(buf: &'a mut Vec<u8>) -> Self {
        buf.clear();
        // Encapsulation header: CDR_LE.
        buf.extend_from_slice(&[0, 1, 0, 0]);
        Self { buf }
    }

    /// Pads to a multiple of `n` counted from the end of the encapsulation header.
    fn align(&mut self, n: usize) {
        let pad = (n - (self.buf.len() - 4) % n) % n;
        self.buf.extend(std::iter::repeat_n(0u8, pad));
    }

    pub(super) fn u64(&mut self, v: u64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub(super) fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub(super) fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    /// A sequence: its length, then (for a non-empty one) padding to the element size and the
    /// elements. Empty sequences get no padding, as in Fast-CDR and the Foxglove/Python readers.
    pub(super) fn f64_seq(&mut self, n: usize, values: impl Iterator<Item = f64>) {
        self.u32(n as u32);
        if n > 0 {
            self.align(8);
        }
        self.buf.reserve(8 * n);
        let mut count = 0;
        for v in values {
            self.buf.extend_from_slice(&v.to_le_bytes());
            count += 1;
        }
        debug_assert_eq!(count, n);
    }

    pub(super) fn f32_seq(&mut self, n: usize, values: impl Iterator<Item = f32>) {
        self.u32(n as u32);
        self.buf.reserve(4 * n);
        for v in values {
            self.buf.extend_from_slice(&v.to_le_bytes());
        }
    }

    pub(super) fn u32_seq(&mut self, n: usize, values: impl Iterator<Item = u32>) {
        self.u32(n as u32);
        self.buf.reserve(4 * n);
        for v in values {
            self.buf.extend_from_slice(&v.to_le_bytes());
        }
    }
}

/// Deserializer of plain CDR, little endian, with every read bounds-checked.
pub(super) struct CdrReader<'a> {
    data: &'a [u8],
    pos: usize,
}

pub(super) type CdrResult<T> = Result<T, String>;

impl<'a> CdrReader<'a> {
    pub(super) fn new(data: &'a [u8]) -> CdrResult<Self> {
        if data.len() < 4 {
            return Err("message shorter than its CDR header".into());
        }
        if data[1] != 1 {
            return Err(format!(
                "unsupported CDR encapsulation kind {} (expected 1, CDR_LE)",
                data[1]
            ));
        }
        Ok(Self { data, pos: 4 })
    }

    fn align(&mut self, n: usize) {
        self.pos += (n - (self.pos - 4) % n) % n;
    }

    /// Bytes left after the current position.
    pub(super) fn remaining(&self) -> usize {
        self.data.len().saturating_sub(self.pos)
    }

    fn take(&mut self, n: usize) -> CdrResult<&'a [u8]> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.data.len())
            .ok_or_else(|| {
                format!(
                    "message ends at byte {} of {}",
                    self.data.len(),
                    self.pos + n
                )
            })?;
        let bytes = &self.data[self.pos..end];
        self.pos = end;
        Ok(bytes)
    }

    pub(super) fn u64(&mut self) -> CdrResult<u64> {
        self.align(8);
        Ok(u64::from_le_bytes(self.take(8)?.try_into().unwrap()))
    }

    pub(super) fn f64(&mut self) -> CdrResult<f64> {
        self.align(8);
        Ok(f64::from_le_bytes(self.take(8)?.try_into().unwrap()))
    }

    fn u32(&mut self) -> CdrResult<u32> {
        self.align(4);
        Ok(u32::from_le_bytes(self.take(4)?.try_into().unwrap()))
    }

    pub(super) fn string(&mut self) -> CdrResult<String> {
        let n = self.u32()? as usize;
        let bytes = self.take(n)?;
        let text = bytes.strip_suffix(&[0]).unwrap_or(bytes);
        String::from_utf8(text.to_vec()).map_err(|_| "string is not UTF-8".to_string())
    }

    /// Length of a sequence of `size`-byte elements, checked against the bytes left.
    fn seq_len(&mut self, size: usize) -> CdrResult<usize> {
        let n = self.u32()? as usize;
        if n > 0 {
            self.align(size);
        }
        if n.saturating_mul(size) > self.data.len().saturating_sub(self.pos) {
            return Err(format!(
                "sequence of {n} elements runs past the message end"
            ));
        }
        Ok(n)
    }

    pub(super) fn f64_seq(&mut self) -> CdrResult<Vec<f64>> {
        let n = self.seq_len(8)?;
        let bytes = self.take(8 * n)?;
        Ok(bytes
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes(b.try_into().unwrap()))
            .collect())
    }

    pub(super) fn f32_seq(&mut self) -> CdrResult<Vec<f32>> {
        let n = self.seq_len(4)?;
        let bytes = self.take(4 * n)?;
        Ok(bytes
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect())
    }

    pub(super) fn u32_seq(&mut self) -> CdrResult<Vec<u32>> {
        let n = self.seq_len(4)?;
        let bytes = self.take(4 * n)?;
        Ok(bytes
            .chunks_exact(4)
            .map(|b| u32::from_le_bytes(b.try_into().unwrap()))
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cdr_layout_matches_the_ros2_rules() {
        // Expectation (XCDR1): u64 at 0, f64 at 8, sequence length at 16, 4 bytes of padding,
        // the first element at 24; an empty sequence gets no padding.
        let mut buf = Vec::new();
        let mut w = CdrWriter::new(&mut buf);
        w.u64(7);
        w.f64(0.5);
        w.f64_seq(1, [2.0].into_iter());
        w.f64_seq(0, std::iter::empty());
        w.f64_seq(1, [3.0].into_iter());
        assert_eq!(&buf[..4], &[0, 1, 0, 0]);
        assert_eq!(
            u32::from_le_bytes(buf[4 + 16..4 + 20].try_into().unwrap()),
            1
        );
        assert_eq!(
            f64::from_le_bytes(buf[4 + 24..4 + 32].try_into().unwrap()),
            2.0
        );
        // Empty sequence: its length at 32, then the next length at 36, its element at 40.
        assert_eq!(
            u32::from_le_bytes(buf[4 + 32..4 + 36].try_into().unwrap()),
            0
        );
        assert_eq!(
            u32::from_le_bytes(buf[4 + 36..4 + 40].try_into().unwrap()),
            1
        );
        assert_eq!(
            f64::from_le_bytes(buf[4 + 40..4 + 48].try_into().unwrap()),
            3.0
        );
        let mut r = CdrReader::new(&buf).unwrap();
        assert_eq!(r.u64().unwrap(), 7);
        assert_eq!(r.f64().unwrap(), 0.5);
        assert_eq!(r.f64_seq().unwrap(), vec![2.0]);
        assert!(r.f64_seq().unwrap().is_empty());
        assert_eq!(r.f64_seq().unwrap(), vec![3.0]);
        assert!(r.f64_seq().is_err());
    }
}

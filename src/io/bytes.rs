//! A little-endian reader over a file's payload for the model formats (`.btfm`, `.lpca`):
//! every read checks the bytes left first, and every count read from the file is checked
//! against them before anything is allocated for it, so a hostile count cannot make a parser
//! allocate more than the file holds.
//!
//! Errors are one-line reasons naming the byte offset; the caller adds the file name.

use half::f16;

/// A parse result whose error is the reason, for a message.
pub type Parse<T> = std::result::Result<T, String>;

/// Reads from a byte slice front to back.
pub struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    /// A reader at the start of `bytes`.
    pub fn new(bytes: &'a [u8]) -> Self {
        Self { bytes, pos: 0 }
    }

    /// The next `n` bytes.
    pub fn take(&mut self, n: usize) -> Parse<&'a [u8]> {
        if self.bytes.len() - self.pos < n {
            return Err(format!("truncated at byte {} (wanted {n} more)", self.pos));
        }
        let s = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    fn array<const N: usize>(&mut self) -> Parse<[u8; N]> {
        Ok(self.take(N)?.try_into().expect("N bytes"))
    }

    /// One byte.
    pub fn u8(&mut self) -> Parse<u8> {
        Ok(self.take(1)?[0])
    }

    /// One byte that must not exceed `max` (`what` names it in the error).
    pub fn u8_at_most(&mut self, max: usize, what: &str) -> Parse<u8> {
        let v = self.u8()?;
        if usize::from(v) > max {
            return Err(format!("{what} {v} exceeds {max}"));
        }
        Ok(v)
    }

    /// A `u16`.
    pub fn u16(&mut self) -> Parse<u16> {
        self.array().map(u16::from_le_bytes)
    }

    /// A `u32`.
    pub fn u32(&mut self) -> Parse<u32> {
        self.array().map(u32::from_le_bytes)
    }

    /// A finite single-precision number, widened.
    pub fn f32(&mut self) -> Parse<f64> {
        let v = f32::from_le_bytes(self.array()?);
        if v.is_finite() {
            Ok(f64::from(v))
        } else {
            Err(format!("non-finite number at byte {}", self.pos - 4))
        }
    }

    /// `count` finite single-precision numbers (checked to fit before allocating).
    pub fn f32s(&mut self, count: usize) -> Parse<Vec<f64>> {
        self.ensure(count, 4, "numbers")?;
        (0..count).map(|_| self.f32()).collect()
    }

    /// `count` `u16` values (checked to fit before allocating).
    pub fn u16s(&mut self, count: usize, what: &str) -> Parse<Vec<u16>> {
        self.ensure(count, 2, what)?;
        let raw = self.take(count * 2)?;
        Ok(raw
            .chunks_exact(2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]))
            .collect())
    }

    /// `count` finite IEEE half-precision numbers, widened (checked to fit before allocating).
    pub fn halves(&mut self, count: usize, what: &str) -> Parse<Vec<f32>> {
        self.ensure(count, 2, what)?;
        let raw = self.take(count * 2)?;
        raw.chunks_exact(2)
            .map(|b| {
                let v = f16::from_bits(u16::from_le_bytes([b[0], b[1]]));
                if v.is_finite() {
                    Ok(v.to_f32())
                } else {
                    Err(format!("{what}: a non-finite number"))
                }
            })
            .collect()
    }

    /// Checks that `count` items of `size` bytes fit in what is left.
    pub fn ensure(&self, count: usize, size: usize, what: &str) -> Parse<()> {
        match count.checked_mul(size) {
            Some(b) if b <= self.bytes.len() - self.pos => Ok(()),
            _ => Err(format!(
                "{what}: {count} values at byte {} exceed the file",
                self.pos
            )),
        }
    }

    /// Succeeds when every byte was read.
    pub fn finish(&self) -> Parse<()> {
        match self.bytes.len() - self.pos {
            0 => Ok(()),
            left => Err(format!("{left} unexpected bytes at the end of the payload")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_read_little_endian_and_overruns_are_errors() {
        let mut bytes = vec![7u8];
        bytes.extend_from_slice(&0x0102u16.to_le_bytes());
        bytes.extend_from_slice(&0x0304_0506u32.to_le_bytes());
        bytes.extend_from_slice(&1.5f32.to_le_bytes());
        bytes.extend_from_slice(&f16::from_f32(-2.0).to_bits().to_le_bytes());
        let mut r = Reader::new(&bytes);
        assert_eq!(r.u8().unwrap(), 7);
        assert_eq!(r.u16().unwrap(), 0x0102);
        assert_eq!(r.u32().unwrap(), 0x0304_0506);
        assert_eq!(r.f32().unwrap(), 1.5);
        assert!(r.finish().unwrap_err().contains("2 unexpected bytes"));
        assert_eq!(r.halves(1, "h").unwrap(), vec![-2.0]);
        r.finish().unwrap();
        assert!(r.u8().unwrap_err().contains("truncated at byte 13"));
    }

    #[test]
    fn hostile_counts_and_bad_numbers_are_refused() {
        let bytes = [0u8; 8];
        let r = Reader::new(&bytes);
        assert!(
            r.ensure(usize::MAX, 2, "x")
                .unwrap_err()
                .contains("exceed the file")
        );
        assert!(r.ensure(5, 2, "x").is_err());
        r.ensure(4, 2, "x").unwrap();
        assert!(Reader::new(&bytes).f32s(3).is_err());
        assert!(
            Reader::new(&bytes)
                .u16s(5, "w")
                .unwrap_err()
                .starts_with("w:")
        );
        assert_eq!(Reader::new(&bytes).u16s(4, "w").unwrap(), vec![0; 4]);
        let nan = f32::NAN.to_le_bytes();
        assert!(Reader::new(&nan).f32().unwrap_err().contains("non-finite"));
        let inf = f16::INFINITY.to_bits().to_le_bytes();
        assert!(
            Reader::new(&inf)
                .halves(1, "h")
                .unwrap_err()
                .contains("non-finite")
        );
        let order = [9u8];
        let err = Reader::new(&order).u8_at_most(6, "order").unwrap_err();
        assert_eq!(err, "order 9 exceeds 6");
    }
}

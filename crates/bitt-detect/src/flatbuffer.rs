//! A bounds-checked reader of FlatBuffers tables, vectors and strings: just what reading a
//! TFLite model needs ([`crate::tflite`]). Every access checks its offsets against the buffer,
//! so a truncated or corrupt file gives an error, never a panic.

/// A table in a FlatBuffers buffer.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Table<'a> {
    buf: &'a [u8],
    pos: usize,
    vtable: usize,
    vtable_len: usize,
}

/// What went wrong, as a sentence (the caller names the file).
pub(crate) type FbResult<T> = Result<T, String>;

fn read<const N: usize>(buf: &[u8], pos: usize) -> FbResult<[u8; N]> {
    pos.checked_add(N)
        .and_then(|end| buf.get(pos..end))
        .map(|s| s.try_into().expect("slice of length N"))
        .ok_or_else(|| {
            format!(
                "offset {pos} is past the end of the file ({} bytes)",
                buf.len()
            )
        })
}

fn u32_at(buf: &[u8], pos: usize) -> FbResult<u32> {
    read::<4>(buf, pos).map(u32::from_le_bytes)
}

fn u16_at(buf: &[u8], pos: usize) -> FbResult<u16> {
    read::<2>(buf, pos).map(u16::from_le_bytes)
}

/// `pos + u32 at pos`: where an offset field points.
fn follow(buf: &[u8], pos: usize) -> FbResult<usize> {
    let off = u32_at(buf, pos)? as usize;
    pos.checked_add(off)
        .filter(|&p| p < buf.len())
        .ok_or_else(|| format!("offset at {pos} points past the end of the file"))
}

impl<'a> Table<'a> {
    /// The root table of a buffer.
    pub(crate) fn root(buf: &'a [u8]) -> FbResult<Self> {
        let pos = follow(buf, 0)?;
        Self::at(buf, pos)
    }

    fn at(buf: &'a [u8], pos: usize) -> FbResult<Self> {
        let soffset = i32::from_le_bytes(read::<4>(buf, pos)?) as i64;
        let vtable = pos as i64 - soffset;
        if vtable < 0 || vtable as usize >= buf.len() {
            return Err(format!("table at {pos} has its vtable outside the file"));
        }
        let vtable = vtable as usize;
        let vtable_len = u16_at(buf, vtable)? as usize;
        if vtable_len < 4 || vtable + vtable_len > buf.len() {
            return Err(format!("vtable at {vtable} has a bad size {vtable_len}"));
        }
        Ok(Table {
            buf,
            pos,
            vtable,
            vtable_len,
        })
    }

    /// Where field `id` lives, or `None` when absent.
    fn field(&self, id: usize) -> FbResult<Option<usize>> {
        let entry = 4 + 2 * id;
        if entry + 2 > self.vtable_len {
            return Ok(None);
        }
        let off = u16_at(self.buf, self.vtable + entry)? as usize;
        Ok((off != 0).then_some(self.pos + off))
    }

    /// A scalar field of `N` little-endian bytes.
    fn scalar<const N: usize>(&self, id: usize) -> FbResult<Option<[u8; N]>> {
        match self.field(id)? {
            Some(p) => read::<N>(self.buf, p).map(Some),
            None => Ok(None),
        }
    }

    pub(crate) fn i8(&self, id: usize, default: i8) -> FbResult<i8> {
        Ok(self.scalar::<1>(id)?.map_or(default, |b| b[0] as i8))
    }

    pub(crate) fn u8(&self, id: usize, default: u8) -> FbResult<u8> {
        Ok(self.scalar::<1>(id)?.map_or(default, |b| b[0]))
    }

    pub(crate) fn bool(&self, id: usize) -> FbResult<bool> {
        Ok(self.u8(id, 0)? != 0)
    }

    pub(crate) fn i32(&self, id: usize, default: i32) -> FbResult<i32> {
        Ok(self.scalar::<4>(id)?.map_or(default, i32::from_le_bytes))
    }

    pub(crate) fn u32(&self, id: usize, default: u32) -> FbResult<u32> {
        Ok(self.scalar::<4>(id)?.map_or(default, u32::from_le_bytes))
    }

    pub(crate) fn u64(&self, id: usize, default: u64) -> FbResult<u64> {
        Ok(self.scalar::<8>(id)?.map_or(default, u64::from_le_bytes))
    }

    /// A sub-table field.
    pub(crate) fn table(&self, id: usize) -> FbResult<Option<Table<'a>>> {
        match self.field(id)? {
            Some(p) => Table::at(self.buf, follow(self.buf, p)?).map(Some),
            None => Ok(None),
        }
    }

    /// A vector field: its element count and where its first element starts.
    fn vector(&self, id: usize, elem: usize) -> FbResult<Option<(usize, usize)>> {
        let Some(p) = self.field(id)? else {
            return Ok(None);
        };
        let start = follow(self.buf, p)?;
        let len = u32_at(self.buf, start)? as usize;
        let data = start + 4;
        let end = len
            .checked_mul(elem)
            .and_then(|n| n.checked_add(data))
            .filter(|&e| e <= self.buf.len())
            .ok_or_else(|| format!("vector at {start} ({len} elements) runs past the end"))?;
        let _ = end;
        Ok(Some((len, data)))
    }

    /// A `[ubyte]` field, empty when absent.
    pub(crate) fn bytes(&self, id: usize) -> FbResult<&'a [u8]> {
        Ok(match self.vector(id, 1)? {
            Some((len, data)) => &self.buf[data..data + len],
            None => &[],
        })
    }

    /// An `[int]` field, empty when absent.
    pub(crate) fn i32s(&self, id: usize) -> FbResult<Vec<i32>> {
        Ok(match self.vector(id, 4)? {
            Some((len, data)) => self.buf[data..data + 4 * len]
                .chunks_exact(4)
                .map(|c| i32::from_le_bytes(c.try_into().expect("4 bytes")))
                .collect(),
            None => Vec::new(),
        })
    }

    /// A `[Table]` field, empty when absent.
    pub(crate) fn tables(&self, id: usize) -> FbResult<Vec<Table<'a>>> {
        match self.vector(id, 4)? {
            Some((len, data)) => (0..len)
                .map(|i| Table::at(self.buf, follow(self.buf, data + 4 * i)?))
                .collect(),
            None => Ok(Vec::new()),
        }
    }

    /// A string field (lossy UTF-8), empty when absent.
    pub(crate) fn string(&self, id: usize) -> FbResult<String> {
        Ok(String::from_utf8_lossy(self.bytes(id)?).into_owned())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hand-built buffer: root table with a u32 (field 0), a [int] (field 1) and a string
    /// (field 2).
    fn sample() -> Vec<u8> {
        let mut b = vec![0u8; 64];
        // root offset -> table at 16
        b[0..4].copy_from_slice(&16u32.to_le_bytes());
        // vtable at 4: size 10, table size 16, fields at +4, +8, +12
        b[4..6].copy_from_slice(&10u16.to_le_bytes());
        b[6..8].copy_from_slice(&16u16.to_le_bytes());
        b[8..10].copy_from_slice(&4u16.to_le_bytes());
        b[10..12].copy_from_slice(&8u16.to_le_bytes());
        b[12..14].copy_from_slice(&12u16.to_le_bytes());
        // table at 16: soffset = 16 - 4 = 12
        b[16..20].copy_from_slice(&12i32.to_le_bytes());
        b[20..24].copy_from_slice(&7u32.to_le_bytes());
        // vector at 32: offset field at 24 -> 32 - 24 = 8
        b[24..28].copy_from_slice(&8u32.to_le_bytes());
        b[32..36].copy_from_slice(&2u32.to_le_bytes());
        b[36..40].copy_from_slice(&(-3i32).to_le_bytes());
        b[40..44].copy_from_slice(&5i32.to_le_bytes());
        // string at 44: field at 28 -> 16
        b[28..32].copy_from_slice(&16u32.to_le_bytes());
        b[44..48].copy_from_slice(&2u32.to_le_bytes());
        b[48..50].copy_from_slice(b"hi");
        b
    }

    #[test]
    fn reads_scalars_vectors_and_strings() {
        let b = sample();
        let t = Table::root(&b).unwrap();
        assert_eq!(t.u32(0, 0).unwrap(), 7);
        assert_eq!(t.i32s(1).unwrap(), vec![-3, 5]);
        assert_eq!(t.string(2).unwrap(), "hi");
        // absent fields take their defaults
        assert_eq!(t.i32(3, 1).unwrap(), 1);
        assert!(t.tables(5).unwrap().is_empty());
    }

    #[test]
    fn truncated_and_corrupt_buffers_are_errors() {
        let b = sample();
        for n in 0..b.len() {
            let cut = &b[..n];
            // Any outcome but a panic; reading everything must fail somewhere when cut short.
            let _ = Table::root(cut).and_then(|t| {
                t.u32(0, 0)?;
                t.i32s(1)?;
                t.string(2)
            });
        }
        let mut bad = b.clone();
        bad[32..36].copy_from_slice(&u32::MAX.to_le_bytes());
        let t = Table::root(&bad).unwrap();
        assert!(t.i32s(1).unwrap_err().contains("past the end"));
        let mut bad = b;
        bad[0..4].copy_from_slice(&1000u32.to_le_bytes());
        assert!(Table::root(&bad).is_err());
    }
}

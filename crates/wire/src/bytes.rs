//! Explicit-offset readers and writers: every field is read at its documented offset in its
//! documented byte order, never by transmuting a struct.

/// Reads fields in sequence from a buffer whose length the caller has checked.
pub(crate) struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
    little_endian: bool,
}

impl<'a> Reader<'a> {
    pub fn le(buf: &'a [u8]) -> Self {
        Self { buf, pos: 0, little_endian: true }
    }
    pub fn be(buf: &'a [u8]) -> Self {
        Self { buf, pos: 0, little_endian: false }
    }
    pub fn pos(&self) -> usize {
        self.pos
    }
    fn take<const N: usize>(&mut self) -> [u8; N] {
        let out: [u8; N] = self.buf[self.pos..self.pos + N].try_into().expect("length checked by the caller");
        self.pos += N;
        out
    }
    pub fn u16(&mut self) -> u16 {
        let b = self.take::<2>();
        if self.little_endian { u16::from_le_bytes(b) } else { u16::from_be_bytes(b) }
    }
    pub fn u32(&mut self) -> u32 {
        let b = self.take::<4>();
        if self.little_endian { u32::from_le_bytes(b) } else { u32::from_be_bytes(b) }
    }
    pub fn i32(&mut self) -> i32 {
        self.u32() as i32
    }
    pub fn f32(&mut self) -> f32 {
        f32::from_bits(self.u32())
    }
    pub fn f32s<const N: usize>(&mut self) -> [f32; N] {
        std::array::from_fn(|_| self.f32())
    }
    pub fn i32s<const N: usize>(&mut self) -> [i32; N] {
        std::array::from_fn(|_| self.i32())
    }
}

/// Writes fields in sequence into a fixed buffer.
pub(crate) struct Writer<'a> {
    buf: &'a mut [u8],
    pos: usize,
    little_endian: bool,
}

impl<'a> Writer<'a> {
    pub fn le(buf: &'a mut [u8]) -> Self {
        Self { buf, pos: 0, little_endian: true }
    }
    pub fn be(buf: &'a mut [u8]) -> Self {
        Self { buf, pos: 0, little_endian: false }
    }
    pub fn pos(&self) -> usize {
        self.pos
    }
    fn put(&mut self, b: &[u8]) {
        self.buf[self.pos..self.pos + b.len()].copy_from_slice(b);
        self.pos += b.len();
    }
    pub fn u16(&mut self, v: u16) {
        self.put(&if self.little_endian { v.to_le_bytes() } else { v.to_be_bytes() });
    }
    pub fn u32(&mut self, v: u32) {
        self.put(&if self.little_endian { v.to_le_bytes() } else { v.to_be_bytes() });
    }
    pub fn i32(&mut self, v: i32) {
        self.u32(v as u32);
    }
    pub fn f32(&mut self, v: f32) {
        self.u32(v.to_bits());
    }
    pub fn f32s(&mut self, v: &[f32]) {
        v.iter().for_each(|x| self.f32(*x));
    }
    pub fn i32s(&mut self, v: &[i32]) {
        v.iter().for_each(|x| self.i32(*x));
    }
}

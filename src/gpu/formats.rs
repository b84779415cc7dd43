//! Storage formats of complex-valued texel layers (MODEL §7): RG32F as is, RG16F scaled per
//! layer by its largest magnitude (so high-order terms do not underflow half floats), and
//! RG16 UNORM normalised per layer by its extrema (thesis eq. 1.1). Packing returns the
//! texel bytes and a per-layer decode `(re_offset, re_scale, im_offset, im_scale)` with
//! `value = offset + stored·scale`, which the shader applies (`rescaledFourierValueAt`).

use ash::vk;

/// How complex layers are stored on the GPU.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum StorageFormat {
    /// 32-bit float pairs: exact to f32 (default).
    #[default]
    Rg32f,
    /// Half-float pairs scaled per layer: ~2⁻¹¹ of each layer's largest magnitude.
    Rg16f,
    /// 16-bit fixed point between each layer's extrema: ~2⁻¹⁷ of each layer's range.
    Unorm16,
}

impl StorageFormat {
    /// The Vulkan format of a texel.
    pub fn vk_format(self) -> vk::Format {
        match self {
            Self::Rg32f => vk::Format::R32G32_SFLOAT,
            Self::Rg16f => vk::Format::R16G16_SFLOAT,
            Self::Unorm16 => vk::Format::R16G16_UNORM,
        }
    }

    /// Bytes per texel.
    pub fn texel_bytes(self) -> usize {
        match self {
            Self::Rg32f => 8,
            Self::Rg16f | Self::Unorm16 => 4,
        }
    }

    /// Value of the shader's `STORAGE` specialisation constant.
    pub fn spec_value(self) -> u32 {
        match self {
            Self::Rg32f => 0,
            Self::Rg16f => 1,
            Self::Unorm16 => 2,
        }
    }
}

impl std::fmt::Display for StorageFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Rg32f => "rg32f",
            Self::Rg16f => "rg16f",
            Self::Unorm16 => "unorm16",
        })
    }
}

/// One layer to pack: its texels `[re, im]` and the extrema `[re_min, re_max, im_min,
/// im_max]` of its values.
pub struct Layer<'a> {
    pub texels: &'a [[f64; 2]],
    pub extrema: [f64; 4],
}

/// Packs `layers` (all the same length) into tightly packed texel bytes, layer after layer,
/// and returns the per-layer decode table.
pub fn pack_layers(layers: &[Layer<'_>], format: StorageFormat) -> (Vec<u8>, Vec<[f32; 4]>) {
    let texels: usize = layers.iter().map(|l| l.texels.len()).sum();
    let mut bytes = Vec::with_capacity(texels * format.texel_bytes());
    let mut decode = Vec::with_capacity(layers.len());
    for layer in layers {
        match format {
            StorageFormat::Rg32f => {
                for t in layer.texels {
                    bytes.extend_from_slice(&(t[0] as f32).to_ne_bytes());
                    bytes.extend_from_slice(&(t[1] as f32).to_ne_bytes());
                }
                decode.push([0.0, 1.0, 0.0, 1.0]);
            }
            StorageFormat::Rg16f => {
                let [a, b, c, d] = layer.extrema;
                let m = a.abs().max(b.abs()).max(c.abs()).max(d.abs());
                let scale = if m.is_finite() && m > 0.0 { m } else { 1.0 };
                for t in layer.texels {
                    bytes.extend_from_slice(&f32_to_f16((t[0] / scale) as f32).to_ne_bytes());
                    bytes.extend_from_slice(&f32_to_f16((t[1] / scale) as f32).to_ne_bytes());
                }
                decode.push([0.0, scale as f32, 0.0, scale as f32]);
            }
            StorageFormat::Unorm16 => {
                let [re_min, re_max, im_min, im_max] = layer.extrema;
                let (re_scale, im_scale) = (span(re_min, re_max), span(im_min, im_max));
                for t in layer.texels {
                    bytes.extend_from_slice(&unorm16(t[0], re_min, re_scale).to_ne_bytes());
                    bytes.extend_from_slice(&unorm16(t[1], im_min, im_scale).to_ne_bytes());
                }
                decode.push([
                    re_min as f32,
                    re_scale as f32,
                    im_min as f32,
                    im_scale as f32,
                ]);
            }
        }
    }
    (bytes, decode)
}

/// `max − min`, or 0 for a constant (or broken) layer, which then decodes to `min`.
fn span(min: f64, max: f64) -> f64 {
    let s = max - min;
    if s.is_finite() && s > 0.0 {
        s
    } else {
        0.0
    }
}

/// Thesis eq. 1.1: `(x − min)/(max − min)` in 16-bit fixed point, rounded to nearest.
fn unorm16(x: f64, min: f64, span: f64) -> u16 {
    if span == 0.0 {
        return 0;
    }
    let f = ((x - min) / span).clamp(0.0, 1.0);
    (f * 65535.0).round() as u16
}

/// IEEE 754 binary16 bits of `x`, rounded to nearest even (subnormals, ±inf and NaN kept).
pub fn f32_to_f16(x: f32) -> u16 {
    let bits = x.to_bits();
    let sign = ((bits >> 16) & 0x8000) as u16;
    let exp = ((bits >> 23) & 0xff) as i32;
    let man = bits & 0x7f_ffff;
    if exp == 0xff {
        return sign | 0x7c00 | if man != 0 { 0x200 } else { 0 };
    }
    let e = exp - 127 + 15;
    if e >= 0x1f {
        return sign | 0x7c00;
    }
    if e <= 0 {
        if e < -10 {
            return sign; // below half the smallest subnormal
        }
        // Subnormal: value / 2⁻²⁴ = (1.m · 2²³) · 2^(e−14).
        let m = man | 0x80_0000;
        let shift = (14 - e) as u32;
        let half = 1u32 << (shift - 1);
        let rem = m & ((1u32 << shift) - 1);
        let mut r = m >> shift;
        if rem > half || (rem == half && r & 1 == 1) {
            r += 1; // a carry into 0x400 is the smallest normal, encoded correctly
        }
        return sign | r as u16;
    }
    let mut r = ((e as u32) << 10) | (man >> 13);
    let rem = man & 0x1fff;
    if rem > 0x1000 || (rem == 0x1000 && r & 1 == 1) {
        r += 1; // a carry into the exponent rounds up correctly, up to infinity
    }
    sign | r as u16
}

/// The value of binary16 bits (for tests and diagnostics).
pub fn f16_to_f32(h: u16) -> f32 {
    let sign = if h & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exp = ((h >> 10) & 0x1f) as i32;
    let man = (h & 0x3ff) as f32;
    match exp {
        0 => sign * man * 2f32.powi(-24),
        0x1f if man == 0.0 => sign * f32::INFINITY,
        0x1f => f32::NAN,
        _ => sign * (1.0 + man / 1024.0) * 2f32.powi(exp - 15),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn half_floats_round_to_nearest_even() {
        for (x, h) in [
            (0.0f32, 0x0000u16),
            (-0.0, 0x8000),
            (1.0, 0x3c00),
            (-2.0, 0xc000),
            (0.1, 0x2e66),
            (65504.0, 0x7bff),
            (65520.0, 0x7c00), // rounds up to infinity
            (2f32.powi(-24), 0x0001),
            (2f32.powi(-25), 0x0000), // tie to even (0)
            (1.5 * 2f32.powi(-25), 0x0001),
            (2f32.powi(-14), 0x0400),
            (f32::INFINITY, 0x7c00),
        ] {
            assert_eq!(f32_to_f16(x), h, "{x}");
        }
        assert!(f16_to_f32(f32_to_f16(f32::NAN)).is_nan());
        // Every half value survives the round trip.
        for h in 0..=0xffffu16 {
            let x = f16_to_f32(h);
            if x.is_nan() {
                continue;
            }
            assert_eq!(f32_to_f16(x), h, "{h:#06x}");
        }
    }

    #[test]
    fn packing_decodes_within_the_format_precision() {
        let texels: Vec<[f64; 2]> = (0..200)
            .map(|i| {
                let t = i as f64 * 0.1;
                [t.sin() * 3e-6, (1.7 * t).cos() * 1e-6 - 2e-7]
            })
            .collect();
        let ext = texels
            .iter()
            .fold([f64::MAX, f64::MIN, f64::MAX, f64::MIN], |e, t| {
                [
                    e[0].min(t[0]),
                    e[1].max(t[0]),
                    e[2].min(t[1]),
                    e[3].max(t[1]),
                ]
            });
        let layer = Layer {
            texels: &texels,
            extrema: ext,
        };
        for (format, tol) in [
            (StorageFormat::Rg32f, 3e-6 * 1e-7),
            (StorageFormat::Rg16f, 3e-6 * 5e-4),
            (StorageFormat::Unorm16, 6e-6 / 65535.0),
        ] {
            let (bytes, decode) = pack_layers(std::slice::from_ref(&layer), format);
            assert_eq!(bytes.len(), texels.len() * format.texel_bytes());
            let d = decode[0];
            for (i, t) in texels.iter().enumerate() {
                let (re, im) = match format {
                    StorageFormat::Rg32f => {
                        let f = |o: usize| {
                            f32::from_ne_bytes(bytes[o..o + 4].try_into().unwrap()) as f64
                        };
                        (f(8 * i), f(8 * i + 4))
                    }
                    _ => {
                        let h = |o: usize| u16::from_ne_bytes([bytes[o], bytes[o + 1]]);
                        let v = |x: u16| {
                            if format == StorageFormat::Rg16f {
                                f16_to_f32(x) as f64
                            } else {
                                x as f64 / 65535.0
                            }
                        };
                        (v(h(4 * i)), v(h(4 * i + 2)))
                    }
                };
                let re = d[0] as f64 + re * d[1] as f64;
                let im = d[2] as f64 + im * d[3] as f64;
                assert!(
                    (re - t[0]).abs() <= tol,
                    "{format} re {i}: {re} vs {}",
                    t[0]
                );
                assert!(
                    (im - t[1]).abs() <= tol,
                    "{format} im {i}: {im} vs {}",
                    t[1]
                );
            }
        }
    }
}

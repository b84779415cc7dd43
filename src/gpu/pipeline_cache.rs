//! The on-disk form of the device's `VkPipelineCache` (the cache itself lives in
//! [`Device`](super::Device), which every pipeline creation uses). A file beside the term
//! cache, one per GPU model: `pipelines-VVVV-DDDD.vkcache`, written atomically.
//!
//! The file is our header, then the bytes of `vkGetPipelineCacheData`. Data is handed to the
//! driver only when both our header and Vulkan's own header (`VkPipelineCacheHeaderVersionOne`)
//! name this device: vendor id, device id and `pipelineCacheUUID` (which changes with the
//! driver build). Drivers must reject foreign data themselves, but some have crashed on
//! it, and a damaged file should cost a recompile, never an error. Anything that does not
//! match is ignored with the reason (no error): the cache is only an optimisation.
//!
//! No Vulkan calls here; no import of the device layer (which imports this).

use std::path::{Path, PathBuf};

/// The device a cache file belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CacheIdentity {
    pub vendor_id: u32,
    pub device_id: u32,
    pub driver_version: u32,
    pub uuid: [u8; 16],
}

/// What loading a cache file did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CacheLoad {
    /// The driver was given this many bytes of cached pipelines.
    Loaded(usize),
    /// No file yet (it is written when the device is dropped).
    Missing,
    /// The file was not used, for this reason; it is overwritten at exit.
    Ignored(String),
}

const MAGIC: &[u8; 8] = b"DIFFRPC\0";
const FORMAT_VERSION: u32 = 1;
/// Magic, format version, vendor, device, driver version, UUID, data length.
const HEADER_LEN: usize = 8 + 4 + 4 + 4 + 4 + 16 + 8;
/// `VkPipelineCacheHeaderVersionOne`: length, version, vendor, device, UUID.
const VK_HEADER_LEN: usize = 4 + 4 + 4 + 4 + 16;
/// `VK_PIPELINE_CACHE_HEADER_VERSION_ONE`.
const VK_HEADER_VERSION_ONE: u32 = 1;
/// Largest cache file read (bytes); real ones are kilobytes to a few megabytes.
pub const MAX_CACHE_BYTES: u64 = 256 << 20;

/// The cache file of `id` in `dir`.
pub fn cache_path(dir: &Path, id: &CacheIdentity) -> PathBuf {
    dir.join(format!(
        "pipelines-{:04x}-{:04x}.vkcache",
        id.vendor_id, id.device_id
    ))
}

/// The file's bytes for the driver's cache `data`.
pub fn encode(id: &CacheIdentity, data: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(HEADER_LEN + data.len());
    out.extend_from_slice(MAGIC);
    for v in [
        FORMAT_VERSION,
        id.vendor_id,
        id.device_id,
        id.driver_version,
    ] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&id.uuid);
    out.extend_from_slice(&(data.len() as u64).to_le_bytes());
    out.extend_from_slice(data);
    out
}

fn u32_le(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

/// The driver data in a cache file's `bytes`, or why it must not be used.
pub fn decode<'a>(id: &CacheIdentity, bytes: &'a [u8]) -> Result<&'a [u8], String> {
    if bytes.len() < HEADER_LEN || &bytes[..8] != MAGIC {
        return Err("not a diffract pipeline cache".into());
    }
    if u32_le(bytes, 8) != FORMAT_VERSION {
        return Err(format!("format version {}", u32_le(bytes, 8)));
    }
    let ours = CacheIdentity {
        vendor_id: u32_le(bytes, 12),
        device_id: u32_le(bytes, 16),
        driver_version: u32_le(bytes, 20),
        uuid: bytes[24..40].try_into().expect("16 bytes"),
    };
    if ours != *id {
        return Err("written by another device or driver".into());
    }
    let len = u64::from_le_bytes(bytes[40..48].try_into().expect("8 bytes"));
    let data = &bytes[HEADER_LEN..];
    if len != data.len() as u64 {
        return Err(format!(
            "truncated: {} of {len} bytes of driver data",
            data.len()
        ));
    }
    // Vulkan's own header: its values are native-endian on the device that wrote them, which
    // is this host (the identity above matched).
    if data.len() < VK_HEADER_LEN {
        return Err("driver data shorter than Vulkan's cache header".into());
    }
    let ne = |at: usize| u32::from_ne_bytes(data[at..at + 4].try_into().expect("4 bytes"));
    let header_len = ne(0) as usize;
    if header_len < VK_HEADER_LEN || header_len > data.len() {
        return Err(format!("Vulkan cache header length {header_len}"));
    }
    if ne(4) != VK_HEADER_VERSION_ONE
        || ne(8) != id.vendor_id
        || ne(12) != id.device_id
        || data[16..32] != id.uuid
    {
        return Err("Vulkan's cache header names another device or driver".into());
    }
    Ok(data)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn id() -> CacheIdentity {
        CacheIdentity {
            vendor_id: 0x10005,
            device_id: 7,
            driver_version: 3,
            uuid: [9; 16],
        }
    }

    /// Driver data as a driver would write it for `id`.
    fn driver_data(id: &CacheIdentity, payload: &[u8]) -> Vec<u8> {
        let mut d = Vec::new();
        for v in [32u32, 1, id.vendor_id, id.device_id] {
            d.extend_from_slice(&v.to_ne_bytes());
        }
        d.extend_from_slice(&id.uuid);
        d.extend_from_slice(payload);
        d
    }

    #[test]
    fn round_trip_and_every_mismatch_is_refused() {
        let data = driver_data(&id(), b"pipelines");
        let file = encode(&id(), &data);
        assert_eq!(decode(&id(), &file), Ok(&data[..]));

        let mut other = id();
        other.uuid[3] ^= 1;
        assert!(decode(&other, &file).is_err(), "another driver build");
        other = id();
        other.device_id += 1;
        assert!(decode(&other, &file).is_err(), "another device");

        assert!(decode(&id(), &file[..file.len() - 1]).is_err(), "truncated");
        assert!(decode(&id(), b"garbage").is_err());
        assert!(decode(&id(), &[]).is_err());
        let mut bad_magic = file.clone();
        bad_magic[0] ^= 0xff;
        assert!(decode(&id(), &bad_magic).is_err());
        // Our header right, Vulkan's wrong (a driver writing for another device).
        let mut foreign = driver_data(&id(), b"x");
        foreign[16] ^= 1;
        assert!(decode(&id(), &encode(&id(), &foreign)).is_err());
        let mut bad_len = driver_data(&id(), b"x");
        bad_len[0] = 200;
        assert!(decode(&id(), &encode(&id(), &bad_len)).is_err());
    }

    #[test]
    fn one_file_per_device_model() {
        let p = cache_path(Path::new("/c"), &id());
        assert_eq!(p, Path::new("/c/pipelines-10005-0007.vkcache"));
    }
}

//! The frame layer of `gpu/`: deferred release (an object retired in a frame stays alive
//! until that frame's fence has signalled, then is dropped; the validation layer would
//! report a buffer destroyed while a submission uses it), the pipeline cache on disk (written,
//! reloaded, a damaged or foreign file ignored without an error), and the rule that only
//! the device layer calls `vkDeviceWaitIdle` (counted), never the viewer's frame path.

mod gpu_util;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use ash::vk;
use diffract::gpu::frames::Frames;
use diffract::gpu::memory::Buffer;
use diffract::gpu::pipeline_cache::CacheLoad;
use diffract::gpu::Device;
use diffract::render::Renderer;
use diffract::spectrum::Expansion;
use gpu_allocator::MemoryLocation;
use gpu_util::device;

/// A buffer that says when it was dropped.
struct Tracked {
    buffer: Buffer,
    dropped: Arc<AtomicBool>,
}

impl Drop for Tracked {
    fn drop(&mut self) {
        self.dropped.store(true, Ordering::SeqCst);
    }
}

fn tracked(dev: &Arc<Device>, name: &str) -> (Tracked, Arc<AtomicBool>) {
    let dropped = Arc::new(AtomicBool::new(false));
    let buffer = Buffer::new(
        dev,
        name,
        256,
        vk::BufferUsageFlags::TRANSFER_DST,
        MemoryLocation::GpuOnly,
    )
    .expect("buffer");
    (
        Tracked {
            buffer,
            dropped: dropped.clone(),
        },
        dropped,
    )
}

/// Records a write of `t`'s buffer, so the frame's submission uses it.
fn use_buffer(dev: &Device, cb: vk::CommandBuffer, t: &Tracked) {
    // SAFETY: cb is recording outside a render pass; the buffer has TRANSFER_DST usage.
    unsafe {
        dev.raw()
            .cmd_fill_buffer(cb, t.buffer.raw, 0, vk::WHOLE_SIZE, 0x3f80_0000)
    };
}

fn alive(flag: &AtomicBool) -> bool {
    !flag.load(Ordering::SeqCst)
}

/// Frame k uses a buffer and retires it; the GPU is held inside frame k (it waits for an
/// event the host sets later), so its fence cannot signal: polling releases nothing and
/// the buffer stays alive. Once the host lets the frame finish, waiting for it drops the
/// buffer, and validation (which reports a buffer destroyed while in use) stays silent.
#[test]
fn retired_object_lives_until_its_frame_fence_signals() {
    let Some(dev) = device() else { return };
    let mut frames = Frames::new(&dev, "test frame", 2, false).expect("frames");
    // SAFETY: live device.
    let event = unsafe {
        dev.raw()
            .create_event(&vk::EventCreateInfo::default(), None)
    }
    .expect("event");

    let (held, held_dropped) = tracked(&dev, "held buffer");
    let cb = frames.begin().expect("begin").cb;
    // SAFETY: cb is recording outside a render pass; the event is set by the host only, so
    // the source stage is HOST (VUID-vkCmdWaitEvents-srcStageMask-01158); waiting outside a
    // render pass for an event set after submission is allowed (-pEvents-01163).
    unsafe {
        dev.raw().cmd_wait_events(
            cb,
            &[event],
            vk::PipelineStageFlags::HOST,
            vk::PipelineStageFlags::TRANSFER,
            &[],
            &[],
            &[],
        )
    };
    use_buffer(&dev, cb, &held);
    frames.retire(held);
    frames.submit(&[], &[]).expect("submit");

    for _ in 0..3 {
        std::thread::sleep(Duration::from_millis(30));
        assert_eq!(frames.release_completed().expect("poll"), 0);
        assert!(alive(&held_dropped), "dropped before its frame's fence");
    }
    assert_eq!(frames.awaiting_release(), 1);

    // SAFETY: the event belongs to this device; setting it from the host is its purpose.
    unsafe { dev.raw().set_event(event) }.expect("set event");
    frames.wait().expect("wait");
    assert!(!alive(&held_dropped), "dropped once the fence signalled");
    assert_eq!(frames.awaiting_release(), 0);

    drop(frames);
    // SAFETY: the submission that waited on it completed.
    unsafe { dev.raw().destroy_event(event, None) };
    assert_eq!(
        dev.validation_messages(),
        0,
        "validation: {:#?}",
        dev.validation_report()
    );
    assert_eq!(
        dev.idle_waits(),
        0,
        "no idle wait while frames were in flight"
    );
}

/// With two frames in flight, an object retired in frame k is released when frame k's slot
/// is begun again (frame k + 2, after waiting for k's fence), not at frame k + 1; objects
/// retired between frames go with the frame submitted last.
#[test]
fn release_follows_the_frame_slots() {
    let Some(dev) = device() else { return };
    let mut frames = Frames::new(&dev, "test frame", 2, false).expect("frames");

    let (a, a_dropped) = tracked(&dev, "a");
    let cb = frames.begin().expect("frame 0").cb;
    use_buffer(&dev, cb, &a);
    frames.retire(a);
    frames.submit(&[], &[]).expect("submit 0");

    let (b, b_dropped) = tracked(&dev, "b");
    let cb = frames.begin().expect("frame 1").cb;
    assert!(alive(&a_dropped), "frame 1 does not release frame 0's list");
    use_buffer(&dev, cb, &b);
    frames.submit(&[], &[]).expect("submit 1");
    // Retired between frames: frame 1 was the last to use it.
    frames.retire(b);

    frames.begin().expect("frame 2");
    assert!(
        !alive(&a_dropped),
        "frame 2 reuses frame 0's slot: released"
    );
    assert!(alive(&b_dropped), "b waits for frame 1's slot");
    frames.submit(&[], &[]).expect("submit 2");
    frames.begin().expect("frame 3");
    assert!(
        !alive(&b_dropped),
        "frame 3 reuses frame 1's slot: released"
    );
    frames.submit(&[], &[]).expect("submit 3");
    assert_eq!(frames.submitted(), 4);
    assert_eq!(frames.retired_total(), 2);

    // A frame begun and abandoned (an out-of-date swapchain image) is begun again in the
    // same slot; what was retired meanwhile stays until that slot's fence.
    let (c, c_dropped) = tracked(&dev, "c");
    frames.begin().expect("frame 4");
    frames.retire(c);
    frames.begin().expect("frame 4 again");
    assert!(alive(&c_dropped));
    frames.submit(&[], &[]).expect("submit 4");
    drop(frames);
    assert!(!alive(&c_dropped), "released when the frames are dropped");
    assert_eq!(
        dev.validation_messages(),
        0,
        "validation: {:#?}",
        dev.validation_report()
    );
    assert_eq!(dev.idle_waits(), 0);
}

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("diffract-frames-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("temp dir");
    d
}

/// Draws a 16² BRDF map (one pipeline) on a renderer whose device uses the pipeline cache
/// of `dir`; returns what loading the cache file did.
fn draw_with_cache(dir: &Path) -> Option<CacheLoad> {
    let mut r = gpu_util::renderer()?;
    let load = r.device().load_pipeline_cache(dir);
    let p = gpu_util::prepare(&gpu_util::small_material(
        "builtin:blazed",
        Expansion::Chebyshev,
        4,
        1,
    ));
    r.render_brdf_map(&p, 30.0, 0.0, 16, None).expect("map");
    gpu_util::assert_no_validation(&r);
    finish(r);
    Some(load)
}

/// Drops the renderer (its device saves the cache).
fn finish(r: Renderer) {
    let canary = r.canary();
    drop(r);
    assert_eq!(canary.count(), 0, "{:#?}", canary.messages());
}

fn cache_file(dir: &Path) -> PathBuf {
    let files: Vec<_> = std::fs::read_dir(dir)
        .expect("cache dir")
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "vkcache"))
        .collect();
    assert_eq!(files.len(), 1, "one pipeline cache file: {files:?}");
    files[0].clone()
}

/// First run: no file, one is written at exit. Second run: the driver gets its bytes.
/// A truncated, a garbage and a foreign file are each ignored with a reason, the draw works
/// and the file is rewritten whole.
#[test]
fn pipeline_cache_round_trip_and_damaged_files() {
    let dir = temp_dir("pipeline-cache");
    let Some(first) = draw_with_cache(&dir) else {
        return;
    };
    assert_eq!(first, CacheLoad::Missing);
    let file = cache_file(&dir);
    let written = std::fs::read(&file).expect("cache file");
    // Our header and at least Vulkan's (lavapipe keeps no pipelines beyond it).
    assert!(
        written.len() >= 48 + 32,
        "header and driver data: {}",
        written.len()
    );

    let second = draw_with_cache(&dir).expect("device");
    match second {
        CacheLoad::Loaded(n) => assert!(n >= 32, "{n} bytes"),
        other => panic!("the file written at exit is loaded: {other:?}"),
    }

    let mut foreign = written.clone();
    foreign[30] ^= 0xff; // inside our header's copy of pipelineCacheUUID
    for (what, bytes) in [
        ("truncated", written[..written.len() / 2].to_vec()),
        ("garbage", b"not a cache at all".repeat(10)),
        ("foreign", foreign),
        ("empty", Vec::new()),
    ] {
        std::fs::write(&file, &bytes).expect("damage");
        match draw_with_cache(&dir).expect("device") {
            CacheLoad::Ignored(why) => eprintln!("{what}: ignored ({why})"),
            other => panic!("{what} file: {other:?}"),
        }
        let rewritten = std::fs::read(&file).expect("rewritten");
        assert!(
            rewritten.len() >= 48 + 32 && rewritten[..8] == written[..8],
            "{what}: the cache is written again at exit"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// No cache directory: the cache stays in memory and nothing is written.
#[test]
fn without_a_cache_dir_nothing_is_written() {
    let Some(r) = gpu_util::renderer() else {
        return;
    };
    assert_eq!(r.device().save_pipeline_cache().expect("save"), None);
    finish(r);
}

/// Every `vkDeviceWaitIdle` goes through `Device::wait_idle` (which counts them), and the
/// viewer calls it only when it is torn down: the counter the viewer test reads covers the
/// whole frame path.
#[test]
fn idle_waits_only_in_the_device_layer_and_viewer_teardown() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut stack = vec![src.clone()];
    let mut checked = 0;
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).expect("src").flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
                continue;
            }
            if p.extension().is_none_or(|x| x != "rs") {
                continue;
            }
            let text = std::fs::read_to_string(&p).expect("source");
            checked += 1;
            let rel = p.strip_prefix(&src).unwrap().to_string_lossy().into_owned();
            if rel != "gpu/context.rs" {
                assert!(
                    !text.contains("device_wait_idle("),
                    "{rel} calls vkDeviceWaitIdle directly (use Device::wait_idle)"
                );
            }
            if rel == "view/app.rs" {
                let calls: Vec<_> = text.match_indices("wait_idle(").map(|(i, _)| i).collect();
                let teardown = text.find("impl Drop for Viewer").expect("Viewer's Drop");
                let after = text[teardown..]
                    .find("\n}\n")
                    .map_or(text.len(), |e| teardown + e);
                assert_eq!(calls.len(), 1, "the viewer waits idle once: {calls:?}");
                assert!(
                    calls.iter().all(|&i| i > teardown && i < after),
                    "the viewer's only idle wait is in its Drop"
                );
            }
        }
    }
    assert!(checked > 30, "scanned {checked} files");
}

//! Teardown: after a renderer has drawn a BRDF map and a mesh and is dropped, the validation
//! layer has reported nothing (it reports objects still alive at vkDestroyDevice) and
//! gpu-allocator found no live allocation. Its own test binary, because the leak counter is
//! process-wide.

mod gpu_util;

use diffract::gpu::context::leaked_allocations;
use diffract::scene::Scene;
use diffract::spectrum::Expansion;

#[test]
fn every_object_and_allocation_is_released() {
    let Some(mut r) = gpu_util::renderer() else {
        return;
    };
    let canary = r.canary();
    let p = gpu_util::prepare(&gpu_util::small_material(
        "builtin:blazed",
        Expansion::Chebyshev,
        4,
        1,
    ));
    r.render_brdf_map(&p, 40.0, 0.0, 16, None).unwrap();
    let mut scene = Scene::default_scene();
    scene.output.width = 16;
    scene.output.height = 16;
    r.render_scene(&scene, &p).unwrap();
    drop(r);
    assert_eq!(
        canary.count(),
        0,
        "validation messages: {:#?}",
        canary.messages()
    );
    assert_eq!(leaked_allocations(), 0);
}

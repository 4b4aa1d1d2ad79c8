//! `World::step` and `World::deflected` allocate nothing (they run in the drive
//! simulation's allocation-free loop).

mod common;

use common::{pos, scenario};
use hal::Axis;
use probebridge_sim::World;
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

struct Counting;

thread_local! {
    static COUNT: Cell<Option<usize>> = const { Cell::new(None) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = COUNT.try_with(|c| c.set(c.get().map(|n| n + 1)));
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocations(f: impl FnOnce()) -> usize {
    COUNT.with(|c| c.set(Some(0)));
    f();
    COUNT.with(|c| c.replace(None)).unwrap()
}

#[test]
fn step_and_deflected_allocate_nothing() {
    let body = "seed = 3\n[probe]\nball_radius = 3.0\nnoise = 0.001\n[truth]\nbacklash_C = 0.01\nEX0C = 0.01\n\
                [[sphere]]\ncenter = [100.0, 0.0, 50.0]\nradius = 12.5\n\
                [[plane]]\npoint = [0.0, 0.0, 0.0]\nnormal = [0.0, 0.0, 1.0]\n\
                [[cylinder]]\npoint = [0.0, 0.0, 0.0]\ndirection = [0.0, 1.0, 0.0]\nradius = 5.0\n";
    let mut w = World::new(&scenario("table-ac", body));
    let at = |c: f64, z: f64| pos([100.0, 30.0, z], &[(Axis::A, 0.0), (Axis::C, c)]);
    let n = allocations(|| {
        let mut edges = 0;
        for i in 0..200 {
            let c = i as f64 * 0.5;
            edges += w.step(&at(c, 60.0), &at(c + 0.5, 40.0)).is_some() as usize;
            edges += w.step(&at(c + 0.5, 40.0), &at(c + 0.5, 60.0)).is_some() as usize;
            let _ = w.deflected(&at(c, 50.0));
            let _ = w.penetration(&at(c, 50.0));
        }
        assert!(edges > 0);
    });
    assert_eq!(n, 0);
}

//! The executor's resident-memory watch (`talus::exec::resident`): a unit that touches memory
//! has a recorded peak above it. In a test binary of its own: the watch reads the process's
//! resident size, which tests running beside it in one process would move (a neighbour freeing
//! its memory between the two readings made it fail in the library's tests).

use talus::exec::resident::{Watch, SAMPLE};
use talus::memory::resident_bytes;

#[test]
fn a_unit_that_touches_memory_has_a_peak_above_it() {
    let w = Watch::start();
    w.begin(7);
    let before = resident_bytes().unwrap();
    let v = vec![1u8; 64 << 20];
    std::thread::sleep(4 * SAMPLE);
    std::hint::black_box(&v);
    drop(v);
    let peak = w.end(7).unwrap();
    assert!(peak >= before + (60 << 20), "peak {peak}, before {before}");
    assert!(w.end(7).is_none(), "a unit ends once");
}

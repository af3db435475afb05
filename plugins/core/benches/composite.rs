//! The CPU reference composite against the memory floor: a plain copy of the same frame,
//! measured in the same run. `cargo bench -p avatarm_core --bench composite`.

mod common;

use std::hint::black_box;
use std::time::Instant;

use avatarm_core::dr::{self, EraseSettings, Photometric, RgbaView};
use common::median;
use criterion::{BenchmarkId, Criterion, Throughput};

/// A frame of `w × h` with a robot-like blob covering about a fifth of it.
struct Inputs {
    w: u32,
    h: u32,
    live: Vec<u8>,
    background: Vec<u8>,
    raw: Vec<u8>,
    alpha: Vec<f32>,
}

fn inputs(w: u32, h: u32) -> Inputs {
    let n = (w * h) as usize;
    let mut live = vec![0u8; n * 4];
    let mut background = vec![0u8; n * 4];
    let mut raw = vec![0u8; n * 4];
    for (i, ((l, b), r)) in live
        .chunks_exact_mut(4)
        .zip(background.chunks_exact_mut(4))
        .zip(raw.chunks_exact_mut(4))
        .enumerate()
    {
        let (x, y) = (
            (i as u32 % w) as f32 / w as f32,
            (i as u32 / w) as f32 / h as f32,
        );
        let v = ((x * 200.0) as u8).wrapping_add((y * 50.0) as u8);
        l.copy_from_slice(&[v, v / 2, 255 - v, 255]);
        b.copy_from_slice(&[v / 3, v, 128, 255]);
        let robot = (x - 0.5).powi(2) / 0.09 + (y - 0.5).powi(2) / 0.16 < 0.5;
        r.copy_from_slice(if robot { &[255; 4] } else { &[0, 0, 0, 255] });
    }
    let mask = dr::threshold_mask(
        &RgbaView::new("raw", w, h, &raw).expect("raw size"),
        w,
        h,
        &[[240, 255]; 4],
        0,
        None,
    )
    .expect("sizes");
    let alpha = mask.iter().map(|&m| f32::from(m)).collect();
    Inputs {
        w,
        h,
        live,
        background,
        raw,
        alpha,
    }
}

fn composite(i: &Inputs) -> Vec<u8> {
    let live = RgbaView::new("live", i.w, i.h, &i.live).expect("live size");
    let bg = RgbaView::new("background", i.w, i.h, &i.background).expect("background size");
    dr::composite(&live, &bg, &i.alpha, 1.0, &Photometric::default()).expect("composite")
}

fn erase(i: &Inputs, settings: &EraseSettings) -> Vec<u8> {
    let live = RgbaView::new("live", i.w, i.h, &i.live).expect("live size");
    let bg = RgbaView::new("background", i.w, i.h, &i.background).expect("background size");
    let raw = RgbaView::new("raw", i.w, i.h, &i.raw).expect("raw size");
    dr::erase_frame(&live, &bg, &raw, settings, &Photometric::default()).expect("erase")
}

fn memcpy(src: &[u8], dst: &mut [u8]) {
    dst.copy_from_slice(src);
}

const SIZES: [(u32, u32); 2] = [(640, 480), (1920, 1080)];

fn benches(c: &mut Criterion) {
    let mut group = c.benchmark_group("composite");
    for (w, h) in SIZES {
        let i = inputs(w, h);
        let label = format!("{w}x{h}");
        group.throughput(Throughput::Bytes(i.live.len() as u64));
        let mut dst = vec![0u8; i.live.len()];
        group.bench_function(BenchmarkId::new("memcpy", &label), |b| {
            b.iter(|| memcpy(black_box(&i.live), black_box(&mut dst)));
        });
        group.bench_function(BenchmarkId::new("composite", &label), |b| {
            b.iter(|| composite(black_box(&i)));
        });
        let settings = EraseSettings {
            dilate_px: 4,
            feather_px: 2,
            ..EraseSettings::default()
        };
        group.bench_function(
            BenchmarkId::new("threshold+feather+composite", &label),
            |b| {
                b.iter(|| erase(black_box(&i), &settings));
            },
        );
    }
    group.finish();
}

/// The median of some timings.
/// The ratio to the memory floor, from timings interleaved in one loop (so both see the same
/// machine state); criterion's own report above has the statistics of each.
fn ratios() {
    println!("\nratio to the memory floor (medians of 31 interleaved runs):");
    for (w, h) in SIZES {
        let i = inputs(w, h);
        let mut dst = vec![0u8; i.live.len()];
        let (mut copy, mut comp) = (Vec::new(), Vec::new());
        for _ in 0..31 {
            let t = Instant::now();
            memcpy(black_box(&i.live), black_box(&mut dst));
            copy.push(t.elapsed());
            let t = Instant::now();
            black_box(composite(black_box(&i)));
            comp.push(t.elapsed());
        }
        let (copy, comp) = (median(copy), median(comp));
        println!(
            "  {w}x{h}: memcpy {:.3} ms, composite {:.3} ms, ratio {:.1}x",
            copy.as_secs_f64() * 1e3,
            comp.as_secs_f64() * 1e3,
            comp.as_secs_f64() / copy.as_secs_f64().max(1e-12)
        );
    }
}

fn main() {
    let mut c = Criterion::default().configure_from_args();
    benches(&mut c);
    c.final_summary();
    ratios();
}

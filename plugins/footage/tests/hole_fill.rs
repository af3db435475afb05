//! The fill of the pixels no frame showed, measured where the truth is known: in a real frame
//! of the Panda (`../shared/data/real/franka_easyhec`), the pixels another frame's robot
//! covers show the lab's background; hidden, then filled from around the hole that both
//! robots make, they are compared with what the camera saw there (PSNR, dB).

use std::path::Path;

use avatarm_core::dr::{self, HoleFill, fill_hole, psnr_in};
use avatarm_core::shared_data::shared_data;

/// A frame (RGB) and its robot silhouette (0/1).
fn frame(dir: &Path, i: usize) -> (Vec<[u8; 3]>, Vec<u8>, u32, u32) {
    let name = format!("{i:06}.png");
    let color = image::open(dir.join("color").join(&name))
        .expect("frame")
        .to_rgb8();
    let mask = image::open(dir.join("mask").join(&name))
        .expect("mask")
        .to_luma8();
    let (w, h) = color.dimensions();
    (
        color.pixels().map(|p| p.0).collect(),
        mask.pixels().map(|p| u8::from(p.0[0] > 127)).collect(),
        w,
        h,
    )
}

fn rgba(rgb: &[[u8; 3]]) -> Vec<u8> {
    rgb.iter().flat_map(|p| [p[0], p[1], p[2], 255]).collect()
}

#[test]
fn telea_fills_the_background_behind_a_real_robot_closer_than_rings() {
    let dir = match shared_data() {
        Ok(d) => d.join("real/franka_easyhec"),
        Err(e) => {
            e.skip("telea_fills_the_background_behind_a_real_robot_closer_than_rings");
            return;
        }
    };
    let (mut rings, mut telea) = (Vec::new(), Vec::new());
    for i in 0..10 {
        let (truth, own, w, h) = frame(&dir, i);
        let (_, other, _, _) = frame(&dir, (i + 5) % 10);
        let (wu, hu) = (w as usize, h as usize);
        // Both robots, grown by 2 px (the segmentation's edge), are unknown; scored: where
        // only the other frame's robot was, the background this frame shows.
        let own = dr::dilate(&own, w, h, 2);
        let other = dr::dilate(&other, w, h, 2);
        let scored: Vec<u8> = own
            .iter()
            .zip(&other)
            .map(|(&a, &b)| u8::from(a == 0 && b != 0))
            .collect();
        if scored.iter().filter(|&&s| s != 0).count() < 500 {
            continue;
        }
        for (fill, out) in [
            (HoleFill::Rings, &mut rings),
            (HoleFill::default(), &mut telea),
        ] {
            let mut known: Vec<bool> = own
                .iter()
                .zip(&other)
                .map(|(&a, &b)| a == 0 && b == 0)
                .collect();
            let mut filled: Vec<[u8; 3]> = truth
                .iter()
                .zip(&known)
                .map(|(&p, &k)| if k { p } else { [0; 3] })
                .collect();
            let started = std::time::Instant::now();
            fill_hole(&mut filled, &mut known, wu, hu, fill);
            let ms = started.elapsed().as_secs_f64() * 1e3;
            let p = psnr_in(&rgba(&filled), &rgba(&truth), &scored).expect("scored");
            out.push((i, p, ms));
        }
    }
    let mean = |v: &[(usize, f64, f64)], k: fn(&(usize, f64, f64)) -> f64| {
        v.iter().map(k).sum::<f64>() / v.len().max(1) as f64
    };
    eprintln!("frame, PSNR rings, PSNR Telea (dB), fill time rings, Telea (ms):");
    for (r, t) in rings.iter().zip(&telea) {
        eprintln!("  {} {:.2} {:.2} {:.1} {:.1}", r.0, r.1, t.1, r.2, t.2);
    }
    let (r, t) = (mean(&rings, |x| x.1), mean(&telea, |x| x.1));
    eprintln!("mean PSNR: rings {r:.2} dB, Telea {t:.2} dB");
    assert!(rings.len() >= 5, "only {} frames scored", rings.len());
    assert!(t > r, "Telea {t:.2} dB, rings {r:.2} dB");
    // Telea wins in most frames, not just on average.
    let wins = rings.iter().zip(&telea).filter(|(r, t)| t.1 > r.1).count();
    assert!(
        wins * 2 > rings.len(),
        "Telea better in {wins} of {}",
        rings.len()
    );
}

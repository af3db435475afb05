//! Overlays drawn for the eye: where a mask lands against where the robot is.

/// The frame (RGBA8, `width` wide) with the mask tinted red over it, image `edges` (0/1 per
/// pixel, as `avatarm calibrate --edges` fits to) in yellow, and the reference mask's outline
/// in green on top: where the mask lands against where the robot is, by eye.
pub fn overlay(
    frame: &[u8],
    mask: &[u8],
    edges: Option<&[u8]>,
    reference: Option<&[u8]>,
    width: u32,
) -> Vec<u8> {
    let w = width as usize;
    let mut out = frame.to_vec();
    for (i, px) in out.chunks_exact_mut(4).enumerate() {
        if edges.is_some_and(|e| e[i] > 0) {
            px.copy_from_slice(&EDGE_COLOUR);
        } else if mask[i] > 0 {
            px[0] = ((u16::from(px[0]) + 255) / 2) as u8;
            px[1] /= 2;
            px[2] /= 2;
        }
    }
    if let Some(r) = reference {
        let h = r.len() / w;
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let edge = r[i] > 0
                    && [(0, -1), (0, 1), (-1, 0), (1, 0)].iter().any(|(dx, dy)| {
                        let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                        nx < 0
                            || ny < 0
                            || nx >= w as i64
                            || ny >= h as i64
                            || r[ny as usize * w + nx as usize] == 0
                    });
                if edge {
                    out[i * 4..i * 4 + 4].copy_from_slice(&[40, 255, 40, 255]);
                }
            }
        }
    }
    out
}

/// The colour [`overlay`] draws image edges in (RGBA8).
pub const EDGE_COLOUR: [u8; 4] = [255, 220, 0, 255];

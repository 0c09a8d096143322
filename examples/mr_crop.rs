//! The README's off / on / difference crop of a mixed-reality replay: three
//! composited frames of the same size, cropped to one rectangle and set side by side with
//! `|on - off| x gain` on the right.
//!
//! `cargo run --example mr_crop -- OFF.png ON.png OUT.png X Y W H [GAIN]`

use image::{Rgb, RgbImage};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 7 {
        return Err("usage: mr_crop OFF.png ON.png OUT.png X Y W H [GAIN]".into());
    }
    let (off, on) = (image::open(&args[0])?.into_rgb8(), image::open(&args[1])?.into_rgb8());
    let n: Vec<u32> = args[3..7].iter().map(|s| s.parse()).collect::<Result<_, _>>()?;
    let (x0, y0, w, h) = (n[0], n[1], n[2], n[3]);
    let gain: f32 = args.get(7).map_or(Ok(8.0), |g| g.parse())?;
    if off.dimensions() != on.dimensions() || x0 + w > on.width() || y0 + h > on.height() {
        return Err("the images must have one size and hold the crop".into());
    }
    let mut out = RgbImage::new(3 * w, h);
    let (mut darker, mut most) = (0u32, 0u8);
    for y in 0..h {
        for x in 0..w {
            let (a, b) = (off.get_pixel(x0 + x, y0 + y), on.get_pixel(x0 + x, y0 + y));
            out.put_pixel(x, y, *a);
            out.put_pixel(w + x, y, *b);
            let d = Rgb([0, 1, 2].map(|c| ((a[c] as f32 - b[c] as f32).abs() * gain).min(255.0) as u8));
            out.put_pixel(2 * w + x, y, d);
            let drop = a[1].saturating_sub(b[1]);
            darker += u32::from(drop >= 8);
            most = most.max(drop);
        }
    }
    out.save(&args[2])?;
    println!("{} pixels darker by 8 or more of 255 (green); the most {most}", darker);
    Ok(())
}

//! Writes the benchmark's synthetic two-layer stack ([`drbokeh::bench::two_layer`]: a
//! soft-edged disc at disparity 0.8 in front of a textured background at 0.1..0.3) as an
//! NPZ, for measuring the CLI path (`drbokeh render --layers`) on large images.
//!
//! Run: `cargo run --release -p drbokeh --example make_stack -- 6000 4000 /work/data/mem/24mp.npz`
//! (generated data stays outside the repository).

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [w, h, out] = args.as_slice() else {
        return Err("usage: make_stack WIDTH HEIGHT OUT.npz".into());
    };
    let stack = drbokeh::bench::two_layer(w.parse()?, h.parse()?);
    drbokeh::io::write_stack(out.as_ref(), &stack)?;
    println!("wrote {out}: {w}x{h}, {} layers", stack.layers.len());
    Ok(())
}

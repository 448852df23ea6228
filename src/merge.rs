//! Parts and `firstshot merge` (docs/DISTRIBUTED.md): a shard writes its raw image sum (its
//! two halves: emission and direct light, then the gathered indirect light,
//! `stages::image_estimate`), the number of estimates of each half per pixel and the
//! fingerprint of its run into a part file beside its image; `merge` adds parts **exactly**
//! and writes the mean of the whole.
//!
//! Exactly: every f32 of a shard's image sum is a multiple of 2^-149 below 2^128, so a sum of
//! any number of them is an integer multiple of 2^-149, held here without rounding in 320
//! bits (`Exact`). Such sums are associative and commutative: the merged image does not
//! depend on the order of the parts, nor on how they were grouped (a merge of merges gives
//! the bits of one merge of all shards). Only the final mean is rounded: the exact sum to
//! f64 (correctly rounded), divided by the count, rounded to f32, and the two halves' means
//! added in f32. For one part this is the shard's own f32 division s / w, bit for bit (f64
//! holds both exactly and rounds their quotient innocuously to f32), so a merge of shard 0
//! of 1 is the unsharded image.
//!
//! Part file layout (little endian): magic "FSPART02", fingerprint u64, run seed u64, shard
//! count u32, width u32, height u32, direct-light estimates per pixel u64, image steps (the
//! gathered half's estimates per pixel) u64, the number of shards it holds u32 and each
//! index u32 (ascending), the scene's path (u32 length + UTF-8), the values' length u64 and
//! the values (r, g, b of each pixel, row by row, the direct half then the gathered half,
//! each an `Exact` as `Exact::encode` writes it), then an FNV-1a 64 checksum of all that
//! precedes it.

use crate::checkpoint::fnv1a;
use crate::image::{Image, write_atomically};
use crate::shard::ShardRun;
use crate::{Error, Result};
use std::path::{Path, PathBuf};

const MAGIC: &[u8; 8] = b"FSPART02";
const LIMBS: usize = 5;
const BYTES: usize = LIMBS * 8;

/// An exact sum of f32 values: a two's complement integer of 320 bits in units of 2^-149
/// (the smallest f32), and which non-finite values went in (`specials`: 1 +inf, 2 -inf,
/// 4 NaN), which decide the result alone, as they would in float arithmetic.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Exact {
    limbs: [u64; LIMBS],
    specials: u8,
}

const PLUS_INF: u8 = 1;
const MINUS_INF: u8 = 2;
const NAN: u8 = 4;

fn negate(limbs: &[u64; LIMBS]) -> [u64; LIMBS] {
    let mut out = [0u64; LIMBS];
    let mut carry = 1u64;
    for i in 0..LIMBS {
        let (v, c) = (!limbs[i]).overflowing_add(carry);
        out[i] = v;
        carry = c as u64;
    }
    out
}

/// 2^k as f64, for k in the normal range.
fn pow2(k: i32) -> f64 {
    debug_assert!((-1022..=1023).contains(&k));
    f64::from_bits(((1023 + k) as u64) << 52)
}

impl Exact {
    pub const ZERO: Exact = Exact { limbs: [0; LIMBS], specials: 0 };

    /// The exact value of `v`.
    pub fn from_f32(v: f32) -> Exact {
        if !v.is_finite() {
            let specials = if v.is_nan() {
                NAN
            } else if v > 0.0 {
                PLUS_INF
            } else {
                MINUS_INF
            };
            return Exact { limbs: [0; LIMBS], specials };
        }
        let bits = v.to_bits();
        let (e, f) = ((bits >> 23) & 0xff, bits & 0x7f_ffff);
        // v = m 2^(shift - 149), m < 2^24, shift <= 253.
        let (m, shift) = if e == 0 { (f, 0) } else { (f | 0x80_0000, e - 1) };
        let value = (m as u128) << (shift % 64);
        let mut limbs = [0u64; LIMBS];
        let at = (shift / 64) as usize;
        limbs[at] = value as u64;
        limbs[at + 1] = (value >> 64) as u64;
        if bits >> 31 == 1 {
            limbs = negate(&limbs);
        }
        Exact { limbs, specials: 0 }
    }

    /// Adds `other`, exactly (two's complement: no bound is near for sums of f32s).
    pub fn add(&mut self, other: &Exact) {
        let mut carry = false;
        for i in 0..LIMBS {
            let (v, c1) = self.limbs[i].overflowing_add(other.limbs[i]);
            let (v, c2) = v.overflowing_add(carry as u64);
            self.limbs[i] = v;
            carry = c1 || c2;
        }
        self.specials |= other.specials;
        if self.specials != 0 {
            // The finite part no longer counts: one form for each such value.
            self.limbs = [0; LIMBS];
        }
    }

    fn negative(&self) -> bool {
        self.limbs[LIMBS - 1] >> 63 == 1
    }

    /// The value rounded to the nearest f64 (ties to even); non-finite values go in as float
    /// addition would take them (+inf and -inf together, or a NaN: NaN).
    pub fn to_f64(&self) -> f64 {
        if self.specials != 0 {
            return if self.specials & NAN != 0 || self.specials == PLUS_INF | MINUS_INF {
                f64::NAN
            } else if self.specials == PLUS_INF {
                f64::INFINITY
            } else {
                f64::NEG_INFINITY
            };
        }
        let negative = self.negative();
        let mag = if negative { negate(&self.limbs) } else { self.limbs };
        let Some(top) = (0..LIMBS).rev().find(|&i| mag[i] != 0) else {
            return 0.0;
        };
        let high_bit = 64 * top + 63 - mag[top].leading_zeros() as usize;
        let value = if high_bit < 64 {
            mag[0] as f64 * pow2(-149)
        } else {
            // The 64 bits from `low` up, with every bit below folded into the lowest (a
            // sticky bit): u64 -> f64 then rounds as the whole number would.
            let low = high_bit - 63;
            let (limb, off) = (low / 64, low % 64);
            let mut bits = mag[limb] >> off;
            if off > 0 && limb + 1 < LIMBS {
                bits |= mag[limb + 1] << (64 - off);
            }
            let below = mag[..limb].iter().any(|&l| l != 0) || (off > 0 && mag[limb] << (64 - off) != 0);
            (bits | below as u64) as f64 * pow2(low as i32 - 149)
        };
        if negative { -value } else { value }
    }

    /// Appends the value: two bytes (lowest non-zero byte b of the 40, count c of bytes
    /// from there up to and with the sign), then those c bytes; zero is `0 0`, non-finite
    /// values `255 specials`.
    pub fn encode(&self, out: &mut Vec<u8>) {
        if self.specials != 0 {
            out.extend_from_slice(&[0xff, self.specials]);
            return;
        }
        let mut bytes = [0u8; BYTES];
        for (i, l) in self.limbs.iter().enumerate() {
            bytes[8 * i..8 * i + 8].copy_from_slice(&l.to_le_bytes());
        }
        let Some(b) = bytes.iter().position(|&x| x != 0) else {
            out.extend_from_slice(&[0, 0]);
            return;
        };
        let negative = self.negative();
        let fill = if negative { 0xff } else { 0 };
        let mut t = (b..BYTES).rev().find(|&i| bytes[i] != fill).unwrap_or(b);
        if (bytes[t] >> 7 == 1) != negative {
            t += 1;
        }
        out.extend_from_slice(&[b as u8, (t - b + 1) as u8]);
        out.extend_from_slice(&bytes[b..=t]);
    }

    /// Reads a value `encode` wrote at `data[*at..]`, moving `at` past it; `None` if the
    /// bytes are not one.
    pub fn decode(data: &[u8], at: &mut usize) -> Option<Exact> {
        let head = data.get(*at..*at + 2)?;
        let (b, c) = (head[0] as usize, head[1] as usize);
        *at += 2;
        if b == 0xff {
            return (c != 0 && c <= 7).then_some(Exact { limbs: [0; LIMBS], specials: c as u8 });
        }
        if c == 0 {
            return (b == 0).then_some(Exact::ZERO);
        }
        if b + c > BYTES {
            return None;
        }
        let body = data.get(*at..*at + c)?;
        *at += c;
        let mut bytes = [0u8; BYTES];
        bytes[b..b + c].copy_from_slice(body);
        if body[c - 1] >> 7 == 1 {
            bytes[b + c..].fill(0xff);
        }
        let mut limbs = [0u64; LIMBS];
        for (i, l) in limbs.iter_mut().enumerate() {
            *l = u64::from_le_bytes(bytes[8 * i..8 * i + 8].try_into().unwrap_or([0; 8]));
        }
        Some(Exact { limbs, specials: 0 })
    }
}

/// A partial result: the exact image sum of one shard or of a merge of several, and what
/// identifies the run it belongs to.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Part {
    /// The run's fingerprint (`render::fingerprint` with the run's seed): the scene and every
    /// option that changes the image.
    pub fingerprint: u64,
    /// The run's seed (`--seed`), before each shard's derivation.
    pub seed: u64,
    pub shard_count: u32,
    pub width: u32,
    pub height: u32,
    /// Direct-light estimates added into every pixel of the first half.
    pub samples: u64,
    /// Image steps: the gathered estimates in every pixel of the second half (0 for
    /// direct-light images).
    pub iterations: u64,
    /// The shards whose sums it holds, ascending.
    pub shards: Vec<u32>,
    /// The scene's path as the shard was given it.
    pub scene: String,
    /// The encoded `Exact` sums, r g b of every pixel.
    values: Vec<u8>,
}

fn bad_part(path: &Path, what: &str) -> Error {
    Error::Usage(format!("{}: not a usable firstshot part ({what})", path.display()))
}

impl Part {
    /// The part of a shard's render: its image sum (`Rendered::image_sum`), whose every pixel
    /// holds the same number of estimates in each half, `iterations` in the second.
    pub fn of_shard(
        run: &ShardRun,
        scene: &str,
        width: u32,
        height: u32,
        sums: &[[f32; 4]],
        iterations: u32,
    ) -> Result<Part> {
        let pixels = width as usize * height as usize;
        let samples = sums.first().map_or(0.0, |s| s[3]);
        if sums.len() != 2 * pixels
            || sums[..pixels].iter().any(|s| s[3] != samples)
            || samples <= 0.0
            || sums[pixels..].iter().any(|s| s[3] != iterations as f32)
        {
            return Err(Error::Gpu("the image sum does not hold the same number of estimates in every pixel".into()));
        }
        let mut values = Vec::with_capacity(sums.len() * 3 * 6);
        for s in sums {
            for &v in &s[..3] {
                Exact::from_f32(v).encode(&mut values);
            }
        }
        Ok(Part {
            fingerprint: run.fingerprint,
            seed: run.run_seed,
            shard_count: run.shard.count,
            width,
            height,
            samples: samples as u64,
            iterations: iterations as u64,
            shards: vec![run.shard.index],
            scene: scene.to_string(),
            values,
        })
    }

    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(64 + self.values.len());
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&self.fingerprint.to_le_bytes());
        out.extend_from_slice(&self.seed.to_le_bytes());
        for v in [self.shard_count, self.width, self.height] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&self.samples.to_le_bytes());
        out.extend_from_slice(&self.iterations.to_le_bytes());
        out.extend_from_slice(&(self.shards.len() as u32).to_le_bytes());
        for k in &self.shards {
            out.extend_from_slice(&k.to_le_bytes());
        }
        out.extend_from_slice(&(self.scene.len() as u32).to_le_bytes());
        out.extend_from_slice(self.scene.as_bytes());
        out.extend_from_slice(&(self.values.len() as u64).to_le_bytes());
        out.extend_from_slice(&self.values);
        let sum = fnv1a(&out);
        out.extend_from_slice(&sum.to_le_bytes());
        out
    }

    /// Parses a part; `path` names it in errors (all usage errors: a bad input).
    pub fn from_bytes(path: &Path, bytes: &[u8]) -> Result<Part> {
        if bytes.len() < 16 || &bytes[..8] != MAGIC {
            return Err(bad_part(path, "no firstshot part header"));
        }
        let (body, sum) = bytes.split_at(bytes.len() - 8);
        if fnv1a(body).to_le_bytes() != sum {
            return Err(bad_part(path, "checksum mismatch: the file is truncated or damaged"));
        }
        let mut at = 8;
        let mut take = |n: usize| -> Result<&[u8]> {
            let s = body.get(at..at + n).ok_or_else(|| bad_part(path, "shorter than its header says"))?;
            at += n;
            Ok(s)
        };
        let u64_of = |s: &[u8]| u64::from_le_bytes(s.try_into().unwrap_or([0; 8]));
        let u32_of = |s: &[u8]| u32::from_le_bytes(s.try_into().unwrap_or([0; 4]));
        let fingerprint = u64_of(take(8)?);
        let seed = u64_of(take(8)?);
        let shard_count = u32_of(take(4)?);
        let width = u32_of(take(4)?);
        let height = u32_of(take(4)?);
        let samples = u64_of(take(8)?);
        let iterations = u64_of(take(8)?);
        let n = u32_of(take(4)?) as usize;
        if n == 0 || n > shard_count as usize {
            return Err(bad_part(path, "its list of shards does not fit its shard count"));
        }
        let mut shards = Vec::with_capacity(n);
        for _ in 0..n {
            shards.push(u32_of(take(4)?));
        }
        if shards.windows(2).any(|w| w[0] >= w[1]) || shards.iter().any(|&k| k >= shard_count) {
            return Err(bad_part(path, "its list of shards is not ascending below its shard count"));
        }
        let len = u32_of(take(4)?) as usize;
        let scene =
            String::from_utf8(take(len)?.to_vec()).map_err(|_| bad_part(path, "the scene path is not UTF-8"))?;
        let len = u64_of(take(8)?) as usize;
        let values = take(len)?.to_vec();
        if at != body.len() {
            return Err(bad_part(path, "bytes after its values"));
        }
        let part = Part { fingerprint, seed, shard_count, width, height, samples, iterations, shards, scene, values };
        // Every value must decode, and there must be exactly three per pixel.
        let mut at = 0;
        for _ in 0..part.value_count() {
            Exact::decode(&part.values, &mut at).ok_or_else(|| bad_part(path, "a damaged value"))?;
        }
        if at != part.values.len() || part.samples == 0 {
            return Err(bad_part(path, "its values do not fit its image size"));
        }
        Ok(part)
    }

    pub fn read(path: &Path) -> Result<Part> {
        // Regular files only, like every other input (a FIFO must not hang the merge).
        let bytes = crate::files::read_named_input(path)?;
        Part::from_bytes(path, &bytes)
    }

    pub fn write(&self, path: &Path) -> Result<()> {
        write_atomically(path, &self.to_bytes())
    }

    fn value_count(&self) -> usize {
        2 * self.width as usize * self.height as usize * 3
    }

    /// The exact sums, r g b of every pixel.
    pub fn sums(&self) -> impl Iterator<Item = Exact> + '_ {
        let mut at = 0;
        (0..self.value_count()).map(move |_| Exact::decode(&self.values, &mut at).unwrap_or_default())
    }

    /// The image: every pixel's sum over the estimates (docs of this module: bit for bit the
    /// renderer's image for one shard).
    pub fn image(&self) -> Image {
        let (direct, gathered) = (self.samples as f64, self.iterations as f64);
        let sums: Vec<f64> = self.sums().map(|s| s.to_f64()).collect();
        let (d, g) = sums.split_at(sums.len() / 2);
        let mean = |s: f64, n: f64| if n > 0.0 { (s / n) as f32 } else { 0.0 };
        let flat: Vec<f32> = d.iter().zip(g).map(|(&d, &g)| mean(d, direct) + mean(g, gathered)).collect();
        let pixels = flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        Image::new(self.width, self.height, pixels)
    }

    /// Shards of the run that this part does not hold.
    pub fn missing(&self) -> Vec<u32> {
        (0..self.shard_count).filter(|k| self.shards.binary_search(k).is_err()).collect()
    }
}

/// `0, 1, 2, 5` as `0-2, 5`.
pub fn ranges(shards: &[u32]) -> String {
    let mut out: Vec<String> = Vec::new();
    let mut i = 0;
    while i < shards.len() {
        let mut j = i;
        while j + 1 < shards.len() && shards[j + 1] == shards[j] + 1 {
            j += 1;
        }
        out.push(if j == i { shards[i].to_string() } else { format!("{}-{}", shards[i], shards[j]) });
        i = j + 1;
    }
    out.join(", ")
}

/// Adds `parts` (read from `paths`, which name them in refusals) into one part: they must be
/// of one run (fingerprint), one shard count and one image size, and hold no shard twice.
/// The result does not depend on their order or grouping.
pub fn merge_parts(parts: &[Part], paths: &[PathBuf]) -> Result<Part> {
    let Some(first) = parts.first() else {
        return Err(Error::Usage("merge: no parts given".into()));
    };
    let name = |i: usize| paths.get(i).map_or_else(|| format!("part {i}"), |p| p.display().to_string());
    for (i, p) in parts.iter().enumerate().skip(1) {
        let against = format!("{} (the first part)", name(0));
        if p.width != first.width || p.height != first.height {
            return Err(Error::Usage(format!(
                "{}: a {}x{} image, {against} is {}x{}: parts of one run have one image size",
                name(i),
                p.width,
                p.height,
                first.width,
                first.height
            )));
        }
        if p.shard_count != first.shard_count {
            return Err(Error::Usage(format!(
                "{}: a part of {} shards, {against} of {}: parts of one run have one shard count",
                name(i),
                p.shard_count,
                first.shard_count
            )));
        }
        if p.fingerprint != first.fingerprint {
            return Err(Error::Usage(format!(
                "{}: belongs to another run than {against}: another scene or other image-changing flags (seed, patch size, resolutions, image size, first shot, burn-in, ...); render all shards with the same scene and flags",
                name(i)
            )));
        }
    }
    let mut owner: std::collections::BTreeMap<u32, usize> = Default::default();
    for (i, p) in parts.iter().enumerate() {
        for &k in &p.shards {
            if let Some(j) = owner.insert(k, i) {
                return Err(Error::Usage(format!(
                    "{} and {} both hold shard {k} of {}: each shard may enter a merge once",
                    name(j),
                    name(i),
                    first.shard_count
                )));
            }
        }
    }
    // Exact sums need no order, but one is kept anyway: by the parts' first shard.
    let mut order: Vec<&Part> = parts.iter().collect();
    order.sort_by_key(|p| p.shards[0]);
    let mut sums: Vec<_> = order.iter().map(|p| p.sums()).collect();
    let mut values = Vec::with_capacity(first.values.len());
    for _ in 0..first.value_count() {
        let mut total = Exact::ZERO;
        for s in &mut sums {
            total.add(&s.next().unwrap_or_default());
        }
        total.encode(&mut values);
    }
    Ok(Part {
        fingerprint: first.fingerprint,
        seed: first.seed,
        shard_count: first.shard_count,
        width: first.width,
        height: first.height,
        samples: parts.iter().map(|p| p.samples).sum(),
        iterations: parts.iter().map(|p| p.iterations).sum(),
        shards: owner.keys().copied().collect(),
        scene: order[0].scene.clone(),
        values,
    })
}

/// What `firstshot merge` is asked to do.
pub struct MergeRequest<'a> {
    /// OUT.exr; OUT.png, OUT.part beside it.
    pub out: &'a Path,
    /// Part files (an `.exr` stands for the `.part` beside it).
    pub parts: &'a [PathBuf],
    /// The stats JSON (default: OUT.stats.json).
    pub stats: Option<&'a Path>,
    /// Refuse to merge while shards are missing.
    pub complete: bool,
    pub quiet: bool,
}

/// The statistics `merge` writes (docs/CLI.md).
#[derive(Debug, Clone, serde::Serialize)]
pub struct MergeStats {
    pub scene: String,
    pub fingerprint: String,
    pub seed: u64,
    pub image: [u32; 2],
    pub shard_count: u32,
    pub shards: Vec<u32>,
    pub missing_shards: Vec<u32>,
    pub complete: bool,
    /// Image steps of all the merged shards together.
    pub iterations: u64,
    /// Estimates per pixel of all the merged shards together.
    pub samples: u64,
    pub parts: Vec<MergedPart>,
    pub total_ms: f64,
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct MergedPart {
    pub path: String,
    pub shards: Vec<u32>,
    pub iterations: u64,
    pub samples: u64,
}

/// `firstshot merge OUT.exr PARTS...`: reads and checks every part, adds them, and only then
/// writes OUT.exr, OUT.png, OUT.part and the stats (each through a temporary name). Bad
/// input is a usage error (nothing written); missing shards are a warning on stderr and in
/// the stats, unless `complete` makes them an error.
pub fn merge_files(request: &MergeRequest) -> Result<MergeStats> {
    let start = std::time::Instant::now();
    let out = request.out;
    let exr = match out.extension().and_then(|e| e.to_str()) {
        Some(e) if e.eq_ignore_ascii_case("exr") => out.to_path_buf(),
        None => out.with_extension("exr"),
        Some(e) => {
            return Err(Error::Usage(format!(
                "merge {}: expected a .exr path (or no extension), not .{e}",
                out.display()
            )));
        }
    };
    let paths: Vec<PathBuf> = request
        .parts
        .iter()
        .map(|p| match p.extension().and_then(|e| e.to_str()) {
            Some(e) if e.eq_ignore_ascii_case("exr") => p.with_extension("part"),
            _ => p.clone(),
        })
        .collect();
    let parts = paths.iter().map(|p| Part::read(p)).collect::<Result<Vec<_>>>()?;
    let merged = merge_parts(&parts, &paths)?;
    let missing = merged.missing();
    if !missing.is_empty() {
        let message = format!(
            "shards {} of {} are missing: the image holds {} of the shards ({} steps); merge their parts in later with `firstshot merge {} {} PARTS...`",
            ranges(&missing),
            merged.shard_count,
            merged.shards.len(),
            merged.iterations,
            exr.display(),
            exr.with_extension("part").display()
        );
        if request.complete {
            return Err(Error::Usage(format!("--complete: {message}")));
        }
        eprintln!("warning: {message}");
    }
    let image = merged.image();
    let stats = MergeStats {
        scene: merged.scene.clone(),
        fingerprint: format!("{:016x}", merged.fingerprint),
        seed: merged.seed,
        image: [merged.width, merged.height],
        shard_count: merged.shard_count,
        shards: merged.shards.clone(),
        missing_shards: missing.clone(),
        complete: missing.is_empty(),
        iterations: merged.iterations,
        samples: merged.samples,
        parts: parts
            .iter()
            .zip(&paths)
            .map(|(p, path)| MergedPart {
                path: path.display().to_string(),
                shards: p.shards.clone(),
                iterations: p.iterations,
                samples: p.samples,
            })
            .collect(),
        total_ms: start.elapsed().as_secs_f64() * 1e3,
    };
    // Every byte first, then the files: a failure to encode writes nothing.
    let attributes = [
        ("firstshot.scene", merged.scene.clone()),
        ("firstshot.seed", merged.seed.to_string()),
        ("firstshot.iterations", merged.iterations.to_string()),
        ("firstshot.shards", format!("{} of {}", ranges(&merged.shards), merged.shard_count)),
    ];
    let exr_bytes = image.exr_bytes(&attributes)?;
    let png_bytes = image.png_bytes(image.auto_exposure())?;
    let json = serde_json::to_string_pretty(&stats).map_err(|e| Error::Usage(format!("encoding the stats: {e}")))?;
    if let Some(dir) = exr.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|source| Error::Io { path: dir.to_path_buf(), source })?;
    }
    let stats_path = request.stats.map_or_else(|| exr.with_extension("stats.json"), Path::to_path_buf);
    let part_path = exr.with_extension("part");
    write_atomically(&part_path, &merged.to_bytes())?;
    write_atomically(&exr, &exr_bytes)?;
    write_atomically(&exr.with_extension("png"), &png_bytes)?;
    write_atomically(&stats_path, json.as_bytes())?;
    if !request.quiet {
        eprintln!(
            "merged {} parts: shards {} of {}, {} steps; wrote {}, {}, {} and {}",
            parts.len(),
            ranges(&merged.shards),
            merged.shard_count,
            merged.iterations,
            exr.display(),
            exr.with_extension("png").display(),
            part_path.display(),
            stats_path.display()
        );
    }
    Ok(stats)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn exact_sum(values: &[f32]) -> Exact {
        let mut s = Exact::ZERO;
        for &v in values {
            s.add(&Exact::from_f32(v));
        }
        s
    }

    fn round_trip(e: &Exact) -> Exact {
        let mut bytes = Vec::new();
        e.encode(&mut bytes);
        let mut at = 0;
        let back = Exact::decode(&bytes, &mut at).expect("decodes");
        assert_eq!(at, bytes.len());
        back
    }

    #[test]
    fn single_values_are_exact_and_round_trip() {
        for v in [
            0.0f32,
            1.0,
            -1.0,
            0.1,
            -0.1,
            f32::MIN_POSITIVE,
            f32::MIN_POSITIVE / 8.0,
            -f32::from_bits(1),
            f32::from_bits(1),
            f32::MAX,
            -f32::MAX,
            123_456.79,
            -256.0,
            255.0,
        ] {
            let e = Exact::from_f32(v);
            assert_eq!(e.to_f64(), v as f64, "{v:e}");
            assert_eq!(round_trip(&e), e, "{v:e}");
        }
        assert!(Exact::from_f32(f32::NAN).to_f64().is_nan());
        assert_eq!(exact_sum(&[1.0, f32::INFINITY]).to_f64(), f64::INFINITY);
        assert_eq!(exact_sum(&[1.0, f32::NEG_INFINITY]).to_f64(), f64::NEG_INFINITY);
        assert!(exact_sum(&[f32::INFINITY, f32::NEG_INFINITY]).to_f64().is_nan());
        assert_eq!(round_trip(&exact_sum(&[f32::INFINITY, 2.0])), exact_sum(&[f32::INFINITY, 2.0]));
    }

    #[test]
    fn sums_are_exact_where_floats_round() {
        // 2^60 + 1 - 2^60: floats lose the 1 in either order, the exact sum keeps it.
        let big = 2f32.powi(60);
        assert_eq!(exact_sum(&[big, 1.0, -big]).to_f64(), 1.0);
        assert_eq!(exact_sum(&[f32::MAX, f32::MAX, -f32::MAX]).to_f64(), f32::MAX as f64);
        assert_eq!(exact_sum(&[f32::from_bits(1), 1e30, -1e30]).to_f64(), f32::from_bits(1) as f64);
        // Rounding to f64 is to nearest: 2^80 + 1 is 2^80, 2^80 + 2^28 + 1 rounds up.
        let two80 = 2f32.powi(80);
        assert_eq!(exact_sum(&[two80, 1.0]).to_f64(), 2f64.powi(80));
        assert_eq!(exact_sum(&[two80, 2f32.powi(27), 1.0]).to_f64(), 2f64.powi(80) + 2f64.powi(28));
        assert_eq!(exact_sum(&[two80, 2f32.powi(27)]).to_f64(), 2f64.powi(80), "a tie goes to even");
        assert_eq!(exact_sum(&[-two80, -2f32.powi(27), -1.0]).to_f64(), -(2f64.powi(80) + 2f64.powi(28)));
    }

    proptest! {
        #[test]
        fn exact_sums_do_not_depend_on_order_or_grouping(
            values in proptest::collection::vec(prop_oneof![
                any::<f32>().prop_filter("finite", |v| v.is_finite()),
                -1e6f32..1e6f32,
                0f32..1e-30f32,
            ], 1..40),
            cut in 0usize..40,
            rotate in 0usize..40,
        ) {
            let whole = exact_sum(&values);
            let mut shuffled = values.clone();
            let n = shuffled.len();
            shuffled.rotate_left(rotate % n);
            shuffled.reverse();
            prop_assert_eq!(exact_sum(&shuffled), whole);
            let (a, b) = values.split_at(cut.min(n));
            let mut grouped = exact_sum(b);
            grouped.add(&exact_sum(a));
            prop_assert_eq!(grouped, whole);
            prop_assert_eq!(round_trip(&whole), whole);
            // Against f64 where f64 is exact: integers below 2^53 in total.
            let ints: Vec<f32> = values.iter().map(|v| (v % 1e6).trunc()).collect();
            prop_assert_eq!(exact_sum(&ints).to_f64(), ints.iter().map(|&v| v as f64).sum::<f64>());
        }

        #[test]
        fn one_part_gives_the_renderers_f32_mean(s in 0f32..1e9f32, w in 1u32..100_000) {
            let w = w as f32;
            prop_assert_eq!((Exact::from_f32(s).to_f64() / w as f64) as f32, s / w);
        }
    }

    /// A part whose direct half holds `values` and gathered half twice them, each with
    /// `samples` estimates.
    fn part(shards: &[u32], count: u32, fingerprint: u64, values: &[f32], samples: u64) -> Part {
        let mut bytes = Vec::new();
        for v in values.iter().copied().chain(values.iter().map(|v| 2.0 * v)) {
            Exact::from_f32(v).encode(&mut bytes);
        }
        Part {
            fingerprint,
            seed: 1,
            shard_count: count,
            width: (values.len() / 3) as u32,
            height: 1,
            samples,
            iterations: samples,
            shards: shards.to_vec(),
            scene: "s.toml".into(),
            values: bytes,
        }
    }

    #[test]
    fn parts_round_trip_and_every_corruption_is_refused() {
        let p = part(&[1, 3], 4, 42, &[0.5, -2.0, 1e-40, 7.0, 0.0, 3.25], 10);
        let bytes = p.to_bytes();
        let path = Path::new("x.part");
        assert_eq!(Part::from_bytes(path, &bytes).unwrap(), p);
        for cut in [0, 7, 20, bytes.len() - 1] {
            assert!(Part::from_bytes(path, &bytes[..cut]).is_err(), "truncated at {cut}");
        }
        for flip in [0, 9, 30, 50, bytes.len() - 3] {
            let mut b = bytes.clone();
            b[flip] ^= 0x10;
            let e = Part::from_bytes(path, &b).unwrap_err();
            assert!(matches!(e, Error::Usage(_)) && e.to_string().contains("x.part"), "flip {flip}: {e}");
        }
    }

    #[test]
    fn merges_refuse_mixed_runs_and_repeated_shards_naming_the_part() {
        let paths: Vec<PathBuf> = ["a.part", "b.part"].iter().map(PathBuf::from).collect();
        let a = part(&[0], 4, 42, &[1.0, 2.0, 3.0], 5);
        for (b, what) in [
            (part(&[1], 4, 43, &[1.0, 2.0, 3.0], 5), "another run"),
            (part(&[1], 3, 42, &[1.0, 2.0, 3.0], 5), "shard count"),
            (part(&[1], 4, 42, &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0], 5), "image size"),
            (part(&[0, 2], 4, 42, &[1.0, 2.0, 3.0], 5), "both hold shard 0"),
        ] {
            let e = merge_parts(&[a.clone(), b], &paths).unwrap_err().to_string();
            assert!(e.contains("b.part") && e.contains(what), "{what}: {e}");
        }
    }

    #[test]
    fn merges_add_exactly_in_any_order_and_grouping() {
        let values = |k: u32| [0.1 * (k + 1) as f32, 1e7 + k as f32, 3e-39 * k as f32];
        let parts: Vec<Part> = (0..4).map(|k| part(&[k], 5, 9, &values(k), 10 + k as u64)).collect();
        let none: Vec<PathBuf> = Vec::new();
        let all = merge_parts(&parts, &none).unwrap();
        assert_eq!(all.shards, [0, 1, 2, 3]);
        assert_eq!(all.missing(), [4]);
        assert_eq!(all.samples, 10 + 11 + 12 + 13);
        let mut reversed = parts.clone();
        reversed.reverse();
        assert_eq!(merge_parts(&reversed, &none).unwrap(), all);
        let left = merge_parts(&[parts[2].clone(), parts[0].clone()], &none).unwrap();
        let right = merge_parts(&[parts[3].clone(), parts[1].clone()], &none).unwrap();
        assert_eq!(merge_parts(&[right, left], &none).unwrap(), all);
        // The image is the exact sum over the estimates: r = 0.1 + 0.2 + 0.3 + 0.4 in f32s
        // in the direct half, twice that in the gathered half.
        let r: f64 = (0..4).map(|k| values(k)[0] as f64).sum();
        assert_eq!(all.image().pixels[0][0], (r / 46.0) as f32 + (2.0 * r / 46.0) as f32);
        assert_eq!(ranges(&[0, 1, 2, 5, 7, 8]), "0-2, 5, 7-8");
    }
}

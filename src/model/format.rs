//! The `.btfm` model file: versioned, checksummed, little-endian, decoded with bounded
//! allocations. The layout is documented byte by byte in `docs/FORMAT.md`.

use std::path::Path;

use super::material::{
    BandMarginals, CoarseSource, DeviationCodes, Exemplar, ExemplarChroma, LIGHTNESS_BANDS,
    LightChroma, LightLightness, LightWeights, LitMarginals, MAX_CHROMA_STEP,
    MAX_EXEMPLAR_COMPONENTS, MAX_EXEMPLAR_STEP, MAX_PERIOD_COMPONENTS, MAX_TILE_SAMPLES,
    MaterialModel, MaterialParts, PeriodicPart, Principal, RangeMap, SubspaceModel,
};
use super::{ModelError, Result};
use crate::btf::{BtfError, DirectionSet};
use crate::decompose::colour_transfer::{
    CHROMA_LEVELS, ChromaSpread, ColourMarginals, Coupling, DIRECTIONS, LIGHTNESS_BINS,
};
use crate::decompose::marginals::{BAND_QUANTILES, QUANTILES, QuantileGrid};
use crate::decompose::{ColourSpace, KlBasis};
use crate::geometry::lattice::Lattice;
use crate::geometry::relight::Shadows;
pub use crate::io::bytes::{Parse, Reader};
use crate::io::envelope;
use crate::mrf::{AnyLevels, BandModel, KindVisitor, Levels, LevelsVisitor, ModelKind};

/// The four bytes every model file starts with.
pub const MAGIC: [u8; 4] = *b"BTFM";
/// The format version this library writes. Version 1 files (no colour space, no band
/// marginals: linear RGB KL), version 2 files (no joint colour tables) and version 3 files (no
/// periodic part), version 4 files (one exemplar crop with a gain per subspace), version 5
/// files (no exemplar chroma), version 6 files (no chroma-lightness coupling), version 7
/// files (no lit lightness tables), version 8 files (exemplar L* deviations always 8-bit),
/// version 9 files (no cast shadows), version 10 files (an exemplar's coarse variation
/// always the MRF's), version 11 files (no light lightness tables), version 12 files (no
/// chroma spreads), version 13 files (an exemplar at every texel), version 14 files (no
/// light weights on the exemplar), version 15 files (no light weights on the periods),
/// version 16 files (no light chroma tables), version 17 files (no exemplar light weights
/// on a lattice), version 18 files (period deviations at 16 bits) and version 20 files (at
/// most 8 exemplar deviations) are still read.
pub const VERSION: u16 = 21;
/// The largest payload accepted, bytes (a model is tens of kilobytes).
pub const MAX_PAYLOAD: u32 = 16 << 20;
/// The most pyramid levels accepted.
pub const MAX_LEVELS: u8 = 16;

/// Appends little-endian values to a model file payload (band model records use it, see
/// [`crate::mrf::BandModel::write`]).
#[derive(Debug, Default)]
pub struct Writer(Vec<u8>);

impl Writer {
    /// Appends a byte.
    pub fn u8(&mut self, v: u8) {
        self.0.push(v);
    }
    /// Appends a little-endian `u16`.
    pub fn u16(&mut self, v: u16) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    /// Appends a little-endian `u32`.
    pub fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    /// Appends `v` in single precision.
    pub fn f32(&mut self, v: f64) {
        self.0.extend_from_slice(&(v as f32).to_le_bytes());
    }
    /// Appends every value in single precision.
    pub fn f32s(&mut self, v: &[f64]) {
        v.iter().for_each(|&x| self.f32(x));
    }
}

/// Writes every level's band model records, finest level first.
struct WriteLevels<'a>(&'a mut Writer);

impl LevelsVisitor for WriteLevels<'_> {
    type Output = ();
    fn visit<M: BandModel>(self, levels: &Levels<M>) {
        levels
            .levels()
            .iter()
            .flatten()
            .for_each(|m| m.write(self.0));
    }
}

/// Reads `levels` levels of band model records of one family.
struct ReadLevels<'r, 'a> {
    reader: &'r mut Reader<'a>,
    levels: usize,
}

impl KindVisitor for ReadLevels<'_, '_> {
    type Output = Parse<AnyLevels>;
    fn visit<M: BandModel>(self) -> Parse<AnyLevels>
    where
        Levels<M>: Into<AnyLevels>,
    {
        let levels = (0..self.levels)
            .map(|_| {
                (0..Levels::<M>::PER_LEVEL)
                    .map(|_| M::read(self.reader))
                    .collect()
            })
            .collect::<Parse<Vec<Vec<M>>>>()?;
        Ok(Levels::new(levels).ok_or("no pyramid levels")?.into())
    }
}

/// Serialises a model to bytes: the envelope's header, the payload ([`to_payload`]) deflated,
/// the CRC-32 of the stored bytes.
pub fn to_bytes(model: &MaterialModel) -> Vec<u8> {
    envelope::seal_deflated(MAGIC, VERSION, &to_payload(model))
}

/// The payload a model file holds, before it is deflated: what the reader parses (docs/FORMAT.md).
pub fn to_payload(model: &MaterialModel) -> Vec<u8> {
    let mut w = Writer(Vec::new());
    w.u8(model.kind().code());
    w.u32(model.width());
    w.u32(model.height());
    w.u8(model.levels() as u8);
    for set in [model.views(), model.lights()] {
        set.write_le(&mut w.0);
    }
    w.u16(model.subspaces().len() as u16);
    let wide = model.subspaces().len() > 256;
    w.u8(if wide { 2 } else { 1 });
    for &c in model.cluster_table() {
        if wide { w.u16(c) } else { w.u8(c as u8) }
    }
    for s in model.subspaces() {
        w.u16(s.representative.0);
        w.u16(s.representative.1);
        w.f32s(&s.kl.mean);
        for row in &s.kl.basis {
            w.f32s(row);
        }
        for q in &s.marginals {
            w.f32s(q);
        }
        s.levels.visit(WriteLevels(&mut w));
    }
    match model.range_map() {
        None => w.u8(0),
        Some(r) => write_range_map(&mut w, r),
    }
    write_colour(&mut w, model);
    write_pair_gains(&mut w, model);
    write_lit_marginals(&mut w, model);
    write_light_lightness(&mut w, model.light_lightness());
    write_light_weights(
        &mut w,
        model.exemplar().and_then(|e| e.light_weights.as_ref()),
    );
    write_light_weights(
        &mut w,
        model.periodic().and_then(|p| p.light_weights.as_ref()),
    );
    write_light_spreads(&mut w, model.light_lightness());
    write_light_chroma(&mut w, model.light_lightness());
    w.0
}

/// Light weights ([`LightWeights`]; the exemplar's since version 15, the periods' since 16): a
/// flag, then the view (u16) and the light rows ([`write_light_rows`]).
fn write_light_weights(w: &mut Writer, weights: Option<&LightWeights>) {
    let Some(l) = weights else {
        w.u8(0);
        return;
    };
    w.u8(1);
    w.u16(l.view as u16);
    write_light_rows(w, &l.weights);
}

/// One row of values a light, all of one length, stored column by column: each column (every
/// light's value in turn) quantised to 8-bit codes.
fn write_light_rows<R: AsRef<[f32]>>(w: &mut Writer, rows: &[R]) {
    for column in light_columns(rows) {
        write_quantised(w, &column, Storage::Byte);
    }
}

/// The rows' values column by column (the file's order).
fn light_columns<R: AsRef<[f32]>>(rows: &[R]) -> Vec<Vec<f64>> {
    let columns = rows.first().map_or(0, |r| r.as_ref().len());
    (0..columns)
        .map(|j| rows.iter().map(|r| f64::from(r.as_ref()[j])).collect())
        .collect()
}

/// Light rows (weights, spreads) as a file stores ([`write_light_rows`]) and reads them back.
pub fn as_stored_light_rows<R: AsRef<[f32]>>(rows: &[R]) -> Vec<Vec<f32>> {
    let columns: Vec<Vec<f32>> = light_columns(rows)
        .iter()
        .map(|c| {
            stored_as(
                &c.iter().map(|&v| v as f32).collect::<Vec<_>>(),
                Storage::Byte,
            )
        })
        .collect();
    (0..rows.len())
        .map(|l| columns.iter().map(|c| c[l]).collect())
        .collect()
}

/// Reads what [`write_light_rows`] wrote: `columns` values for each of `lights` lights.
fn read_light_rows(
    r: &mut Reader,
    lights: usize,
    columns: usize,
    what: &str,
) -> Parse<Vec<Vec<f32>>> {
    r.ensure(columns, 8 + lights, what)?;
    let columns = (0..columns)
        .map(|_| read_stored(r, lights, Storage::Byte, what))
        .collect::<Parse<Vec<_>>>()?;
    Ok((0..lights)
        .map(|l| columns.iter().map(|c| c[l]).collect())
        .collect())
}

/// Reads what [`write_light_weights`] wrote, for `lights` lights and `deviations`
/// deviations.
fn read_light_weights(
    r: &mut Reader,
    lights: usize,
    deviations: usize,
) -> Parse<Option<LightWeights>> {
    if r.u8_at_most(1, "light weights flag")? == 0 {
        return Ok(None);
    }
    let view = usize::from(r.u16()?);
    let weights = read_light_rows(r, lights, deviations, "light weight")?;
    Ok(Some(LightWeights { view, weights }))
}

/// The version 16 band spreads of the light lightness tables ([`LightLightness::spreads`]): a
/// flag, then the light rows ([`write_light_rows`]), [`LIGHTNESS_BANDS`] values a light.
fn write_light_spreads(w: &mut Writer, tables: Option<&LightLightness>) {
    write_flagged_light_rows(w, tables.and_then(|t| t.spreads.as_deref()));
}

/// A flag, then the light rows ([`write_light_rows`]) where there are `rows`.
fn write_flagged_light_rows<R: AsRef<[f32]>>(w: &mut Writer, rows: Option<&[R]>) {
    let Some(rows) = rows else {
        w.u8(0);
        return;
    };
    w.u8(1);
    write_light_rows(w, rows);
}

/// Reads what [`write_flagged_light_rows`] wrote, `columns` values for each of `lights`
/// lights, and hands the rows to `store` with `tables`, the light lightness tables they
/// belong to (which must be there when the flag says rows follow).
fn read_flagged_light_rows(
    r: &mut Reader,
    tables: Option<&mut LightLightness>,
    (lights, columns): (usize, usize),
    what: &str,
    store: impl FnOnce(&mut LightLightness, Vec<Vec<f32>>),
) -> Parse<()> {
    if r.u8_at_most(1, &format!("{what} flag"))? == 0 {
        return Ok(());
    }
    let Some(t) = tables else {
        return Err(format!("{what}s without light lightness tables"));
    };
    store(t, read_light_rows(r, lights, columns, what)?);
    Ok(())
}

/// Reads what [`write_light_spreads`] wrote into `tables` (which must be there when the flag
/// says spreads follow), for `lights` lights.
fn read_light_spreads(
    r: &mut Reader,
    tables: Option<&mut LightLightness>,
    lights: usize,
) -> Parse<()> {
    let shape = (lights, LIGHTNESS_BANDS);
    read_flagged_light_rows(r, tables, shape, "light band spread", |t, rows| {
        t.spreads = Some(
            rows.into_iter()
                .map(|row| std::array::from_fn(|k| row[k]))
                .collect(),
        );
    })
}

/// The version 17 chroma tables of the light lightness tables ([`LightLightness::chroma`]): a
/// flag, then the light rows ([`write_light_rows`]), a light's a* quantiles then its b*
/// quantiles. Stored by quantile across the lights, a byte a value: each quantile's range
/// over the lights is far narrower than a table's range.
fn write_light_chroma(w: &mut Writer, tables: Option<&LightLightness>) {
    let rows = tables.and_then(|t| t.chroma.as_deref()).map(chroma_rows);
    write_flagged_light_rows(w, rows.as_deref());
}

/// A light's chroma tables as one row of values (a* then b*).
fn chroma_rows(chroma: &[LightChroma]) -> Vec<Vec<f32>> {
    chroma.iter().map(|c| c.concat()).collect()
}

/// The tables of a row of [`chroma_rows`], each made non-decreasing: the quantiles are coded
/// over ranges of their own, so rounding can set equal neighbours apart by half a code.
fn chroma_of_row(row: &[f32]) -> LightChroma {
    std::array::from_fn(|c| {
        let mut table: [f32; QUANTILES] = std::array::from_fn(|k| row[c * QUANTILES + k]);
        for k in 1..QUANTILES {
            table[k] = table[k].max(table[k - 1]);
        }
        table
    })
}

/// Light chroma tables as a file stores ([`write_light_chroma`]) and reads them back.
pub fn as_stored_light_chroma(chroma: &[LightChroma]) -> Vec<LightChroma> {
    as_stored_light_rows(&chroma_rows(chroma))
        .iter()
        .map(|row| chroma_of_row(row))
        .collect()
}

/// Reads what [`write_light_chroma`] wrote into `tables` (which must be there when the flag
/// says tables follow), for `lights` lights.
fn read_light_chroma(
    r: &mut Reader,
    tables: Option<&mut LightLightness>,
    lights: usize,
) -> Parse<()> {
    let shape = (lights, 2 * QUANTILES);
    read_flagged_light_rows(r, tables, shape, "light chroma quantile", |t, rows| {
        t.chroma = Some(rows.iter().map(|row| chroma_of_row(row)).collect());
    })
}

/// The version 12 light lightness tables ([`LightLightness`]): a flag, then the view (u16) and
/// one table a light.
fn write_light_lightness(w: &mut Writer, tables: Option<&LightLightness>) {
    let Some(t) = tables else {
        w.u8(0);
        return;
    };
    w.u8(1);
    w.u16(t.view as u16);
    for table in &t.tables {
        write_quantised(w, &table.lightness, Storage::Double);
    }
}

/// Reads what [`write_light_lightness`] wrote, for `lights` lights.
fn read_light_lightness(r: &mut Reader, lights: usize) -> Parse<Option<LightLightness>> {
    if r.u8_at_most(1, "light lightness flag")? == 0 {
        return Ok(None);
    }
    let view = usize::from(r.u16()?);
    r.ensure(lights, TABLE_BYTES, "light lightness tables")?;
    let tables = (0..lights)
        .map(|_| {
            Ok(LitMarginals {
                lightness: read_table(r, BAND_QUANTILES, "light lightness quantile")?,
            })
        })
        .collect::<Parse<Vec<_>>>()?;
    Ok(Some(LightLightness {
        view,
        tables,
        spreads: None,
        chroma: None,
    }))
}

/// Bytes one quantile table at [`BAND_QUANTILES`] probabilities takes in the file (band,
/// colour, lit and light tables): its range (two f32) and a u16 a quantile.
const TABLE_BYTES: usize = 8 + 2 * BAND_QUANTILES;

/// Bytes the light lightness tables take in the file beyond their flag (0 without them).
pub fn light_lightness_bytes(model: &MaterialModel) -> usize {
    model
        .light_lightness()
        .map_or(0, light_lightness_record_bytes)
}

/// Bytes [`write_light_lightness`] writes for `t` after the flag (the view and the tables),
/// and [`write_light_spreads`] and [`write_light_chroma`] after theirs.
fn light_lightness_record_bytes(t: &LightLightness) -> usize {
    let rows = |columns: usize, lights: usize| columns * (8 + lights);
    let spreads = t
        .spreads
        .as_ref()
        .map_or(0, |s| rows(LIGHTNESS_BANDS, s.len()));
    let chroma = t
        .chroma
        .as_ref()
        .map_or(0, |c| rows(2 * QUANTILES, c.len()));
    2 + t.tables.len() * TABLE_BYTES + spreads + chroma
}

/// The version 8 lit lightness tables ([`LitMarginals`]): a flag, then one table a subspace
/// (every subspace has one or none does).
fn write_lit_marginals(w: &mut Writer, model: &MaterialModel) {
    let tables: Option<Vec<&LitMarginals>> = model
        .subspaces()
        .iter()
        .map(|s| s.lit_marginals.as_ref())
        .collect();
    w.u8(u8::from(tables.is_some()));
    for lit in tables.into_iter().flatten() {
        write_quantised(w, &lit.lightness, Storage::Double);
    }
}

/// Reads what [`write_lit_marginals`] wrote into the subspace models.
fn read_lit_marginals(r: &mut Reader, subspaces: &mut [SubspaceModel]) -> Parse<()> {
    if r.u8_at_most(1, "lit table flag")? == 0 {
        return Ok(());
    }
    r.ensure(subspaces.len(), TABLE_BYTES, "lit lightness tables")?;
    for s in subspaces.iter_mut() {
        s.lit_marginals = Some(LitMarginals {
            lightness: read_table(r, BAND_QUANTILES, "lit lightness quantile")?,
        });
    }
    Ok(())
}

/// Bytes the lit lightness tables take in the file (0 without them).
pub fn lit_marginal_bytes(model: &MaterialModel) -> usize {
    let subspaces = model.subspaces();
    if subspaces.iter().all(|s| s.lit_marginals.is_some()) {
        subspaces.len() * TABLE_BYTES
    } else {
        0
    }
}

/// Codes per octave of a stored pair gain: a step of 2.2 %, finer than a visible brightness
/// step.
const GAIN_CODES_PER_OCTAVE: f64 = 32.0;
/// The code of gain 1.
const GAIN_CODE_ONE: f64 = 128.0;

/// The byte a pair gain is stored as: `round(32 log2 g) + 128`, so gains from 1/16 to 15.7.
fn gain_code(gain: f32) -> u8 {
    (GAIN_CODES_PER_OCTAVE * f64::from(gain).log2() + GAIN_CODE_ONE)
        .round()
        .clamp(0.0, 255.0) as u8
}

/// The gain a stored byte means (see [`gain_code`]).
fn gain_of(code: u8) -> f32 {
    ((f64::from(code) - GAIN_CODE_ONE) / GAIN_CODES_PER_OCTAVE).exp2() as f32
}

/// Pair gains as a file stores and reads them back: what analysis keeps.
pub fn as_stored_gains(gains: &[f32]) -> Vec<f32> {
    gains.iter().map(|&g| gain_of(gain_code(g))).collect()
}

/// The version 5 pair gains: a flag, then a byte a pair ([`gain_code`]), view-major.
fn write_pair_gains(w: &mut Writer, model: &MaterialModel) {
    let gains = model.pair_gains();
    if gains.is_empty() {
        w.u8(0);
        return;
    }
    w.u8(1);
    for &g in gains {
        w.u8(gain_code(g));
    }
}

/// Reads what [`write_pair_gains`] wrote for `pairs` pairs.
fn read_pair_gains(r: &mut Reader, pairs: usize) -> Parse<Vec<f32>> {
    match r.u8()? {
        0 => Ok(Vec::new()),
        1 => {
            r.ensure(pairs, 1, "pair gains")?;
            (0..pairs).map(|_| Ok(gain_of(r.u8()?))).collect()
        }
        f => Err(format!("unknown pair gain flag {f}")),
    }
}

/// The version 2 tail: the colour space, then the band quantile tables if any; version 3 adds
/// the joint colour tables if any.
fn write_colour(w: &mut Writer, model: &MaterialModel) {
    let space = model
        .subspaces()
        .first()
        .map_or(ColourSpace::Lab, |s| s.kl.space);
    w.u8(match space {
        ColourSpace::LinearRgb => 0,
        ColourSpace::Lab => 1,
    });
    let grid = model
        .subspaces()
        .first()
        .map_or(QuantileGrid::NormalTails, |s| s.marginal_grid);
    w.u8(match grid {
        QuantileGrid::Uniform => 0,
        QuantileGrid::NormalTails => 1,
    });
    let with_bands = model.subspaces().iter().all(|s| s.band_marginals.is_some());
    w.u8(if with_bands { BAND_QUANTILES as u8 } else { 0 });
    for s in model.subspaces().iter().filter(|_| with_bands) {
        for table in s
            .band_marginals
            .iter()
            .flat_map(|b| b.tables.iter().flatten())
        {
            write_quantised(w, table, Storage::Double);
        }
    }
    let with_colours = model
        .subspaces()
        .iter()
        .all(|s| s.colour_marginals.is_some());
    w.u8(if with_colours { DIRECTIONS as u8 } else { 0 });
    for s in model.subspaces().iter().filter(|_| with_colours) {
        for table in s.colour_marginals.iter().flat_map(|c| &c.tables) {
            write_quantised(w, table, Storage::Double);
        }
    }
    // Version 7: the chroma-lightness coupling of every subspace, or a zero flag.
    let couplings = couplings(model);
    w.u8(u8::from(!couplings.is_empty()));
    for coupling in couplings {
        w.f32s(&coupling.concat());
    }
    // Version 13: how many chroma bands every subspace keeps the spread of (0: none), then
    // each subspace's (a*, b*) spread per band (`MaterialModel::new` makes the counts equal).
    let spreads = chroma_spreads(model);
    w.u8(spreads.first().map_or(0, |s| s.len() as u8));
    for spread in spreads {
        w.f32s(&spread.concat());
    }
    match model.exemplar() {
        None => w.u8(0),
        Some(e) => {
            w.u8(if e.chroma.is_some() { 2 } else { 1 });
            w.u16(e.rows as u16);
            w.u16(e.cols as u16);
            // Version 9: the code width of the L* deviations.
            let deviations = Storage::of(e.deviation_codes);
            w.u8(deviations.bits());
            // Version 11: where the L* coarser than half a patch comes from.
            w.u8(match e.coarse {
                CoarseSource::Mrf => 0,
                CoarseSource::Laid => 1,
            });
            // Version 14: texels per exemplar sample.
            w.u8(e.step as u8);
            write_principal(w, &e.lightness, (Storage::Byte, deviations));
            if let Some(c) = &e.chroma {
                w.u8(c.step as u8);
                write_principal(w, &c.fields, (Storage::Byte, Storage::Byte));
            }
        }
    }
    write_periodic(w, model);
}

/// How the periods are stored: the mean period at 16 bits, its deviations at 8 bits from
/// version 19 (16 before).
const PERIOD_STORAGE: (Storage, Storage) = (Storage::Single, Storage::Byte);

/// The version 4 periodic part: flag, periods, samples, the tiles and the range map's period;
/// from version 20 the colour planes each deviation keeps ([`deviation_planes`]) before them.
fn write_periodic(w: &mut Writer, model: &MaterialModel) {
    match model.periodic() {
        None => w.u8(0),
        Some(p) => write_periodic_part(w, p),
    }
}

/// [`write_periodic`] for a model with a periodic part: flag 1 and the part.
fn write_periodic_part(w: &mut Writer, p: &PeriodicPart) {
    w.u8(1);
    w.f32(p.lattice.rows);
    w.f32(p.lattice.cols);
    w.u8(p.rows as u8);
    w.u8(p.cols as u8);
    let planes = deviation_planes(p);
    w.u8(planes as u8);
    write_principal(w, &written_periods(p, planes), PERIOD_STORAGE);
    if let Some(h) = &p.heights {
        let values: Vec<f64> = h.iter().map(|&v| f64::from(v)).collect();
        write_quantised(w, &values, Storage::Single);
    }
}

/// Colour planes a period deviation keeps in a version 20 file: 1 where every deviation is
/// grey ([`PeriodicPart::grey_deviations`]: a third of the bytes), 3 otherwise.
fn deviation_planes(p: &PeriodicPart) -> usize {
    if p.grey_deviations() { 1 } else { 3 }
}

/// The periods as [`write_periodic`] writes them: each deviation cut to its first `planes`
/// colour planes (the mean whole).
fn written_periods(p: &PeriodicPart, planes: usize) -> Principal {
    let mut written = p.periods.clone();
    for d in written.basis.iter_mut().skip(1) {
        d.truncate(planes * p.rows * p.cols);
    }
    written
}

/// Fields stored as a mean and principal deviations: the number of deviations, each basis
/// field quantised (the mean as `storage.0`, the deviations as `storage.1`), then every
/// subspace's weights.
fn write_principal(w: &mut Writer, p: &Principal, storage: (Storage, Storage)) {
    w.u8((p.basis.len() - 1) as u8);
    for (j, field) in p.basis.iter().enumerate() {
        let values: Vec<f64> = field.iter().map(|&v| f64::from(v)).collect();
        write_quantised(w, &values, if j == 0 { storage.0 } else { storage.1 });
    }
    for weights in &p.weights {
        for &v in weights {
            w.f32(f64::from(v));
        }
    }
}

/// Bytes [`write_principal`] writes for `p`.
fn principal_bytes(p: &Principal, storage: (Storage, Storage)) -> usize {
    1 + p
        .basis
        .iter()
        .enumerate()
        .map(|(j, b)| 8 + if j == 0 { storage.0 } else { storage.1 }.code_bytes(b.len()))
        .sum::<usize>()
        + 4 * p.weights.iter().map(Vec::len).sum::<usize>()
}

/// The range map: its flag (1: heights alone; 2: and strengths; 3: and cast shadows), size,
/// step, quantised heights and, with flags 2 and 3, the strengths.
fn write_range_map(w: &mut Writer, r: &RangeMap) {
    w.u8(match (r.strength.is_empty(), r.shadows) {
        (true, _) => 1,
        (false, Shadows::Attached) => 2,
        (false, Shadows::Cast) => 3,
    });
    w.u16(r.rows as u16);
    w.u16(r.cols as u16);
    w.u16(r.step as u16);
    let heights: Vec<f64> = r.heights.iter().map(|&h| f64::from(h)).collect();
    write_quantised(w, &heights, Storage::Single);
    if !r.strength.is_empty() {
        w.u16(r.strength.len() as u16);
        for &k in &r.strength {
            w.f32(f64::from(k));
        }
    }
}

/// Bytes the range map takes in the file, its flag included (1 without one).
pub fn range_map_bytes(model: &MaterialModel) -> usize {
    model.range_map().map_or(1, range_map_record_bytes)
}

/// Bytes [`write_range_map`] writes for `r`: flag, size and step (7), the heights' low and
/// quantum (8) and codes, and the strengths with their count.
fn range_map_record_bytes(r: &RangeMap) -> usize {
    let strengths = if r.strength.is_empty() {
        0
    } else {
        2 + 4 * r.strength.len()
    };
    7 + 8 + Storage::Single.code_bytes(r.rows * r.cols) + strengths
}

/// Bytes the periodic part takes in the file (1 without one).
pub fn periodic_bytes(model: &MaterialModel) -> usize {
    model.periodic().map_or(1, |p| {
        periodic_bytes_of(p) + light_weights_bytes(p.light_weights.as_ref())
    })
}

/// Bytes [`write_periodic`] writes for `p`: flag, lattice and samples (11), the deviations'
/// planes, the periods and the range map's period.
fn periodic_bytes_of(p: &PeriodicPart) -> usize {
    let heights = p.heights.as_ref().map_or(0, |_| 8 + 2 * p.rows * p.cols);
    12 + principal_bytes(&written_periods(p, deviation_planes(p)), PERIOD_STORAGE) + heights
}

/// Bytes [`write_light_weights`] writes for `weights` after its flag.
fn light_weights_bytes(weights: Option<&LightWeights>) -> usize {
    weights.map_or(0, |l| {
        let deviations = l.weights.first().map_or(0, Vec::len);
        2 + deviations * (8 + l.weights.len())
    })
}

/// Bytes the band quantile tables take in the file (0 unless every subspace has them: the
/// writer writes all or none).
pub fn band_marginal_bytes(model: &MaterialModel) -> usize {
    let subspaces = model.subspaces();
    if subspaces.iter().all(|s| s.band_marginals.is_some()) {
        subspaces.len() * model.levels() * 3 * TABLE_BYTES
    } else {
        0
    }
}

/// Bytes the structure exemplar takes in the file (0 without one).
pub fn exemplar_bytes(model: &MaterialModel) -> usize {
    model.exemplar().map_or(0, |e| {
        let chroma = e.chroma.as_ref().map_or(0, |c| {
            1 + principal_bytes(&c.fields, (Storage::Byte, Storage::Byte))
        });
        let lightness = (Storage::Byte, Storage::of(e.deviation_codes));
        let lights = light_weights_bytes(e.light_weights.as_ref());
        6 + principal_bytes(&e.lightness, lightness) + chroma + lights
    })
}

/// One optional part of every subspace's colour tables (`part`: the chroma-lightness
/// coupling, the chroma spread) as the file holds it: for all subspaces, or for none when one
/// lacks it (colour tables without a coupling are read from files before version 7, without a
/// spread from files before version 13).
fn colour_parts<'a, T>(
    model: &'a MaterialModel,
    part: impl Fn(&'a ColourMarginals) -> Option<&'a T>,
) -> Vec<&'a T> {
    model
        .subspaces()
        .iter()
        .map(|s| part(s.colour_marginals.as_ref()?))
        .collect::<Option<Vec<_>>>()
        .unwrap_or_default()
}

/// Every subspace's chroma-lightness coupling, or none ([`colour_parts`]).
fn couplings(model: &MaterialModel) -> Vec<&Coupling> {
    colour_parts(model, |c| c.coupling.as_ref())
}

/// Every subspace's chroma spread, or none ([`colour_parts`]).
fn chroma_spreads(model: &MaterialModel) -> Vec<&ChromaSpread> {
    colour_parts(model, |c| c.chroma_spread.as_ref())
}

/// Bytes the joint colour tables, their chroma-lightness couplings and their chroma spreads
/// take in the file, as [`write_colour`] writes them (0 without tables).
pub fn colour_marginal_bytes(model: &MaterialModel) -> usize {
    let subspaces = model.subspaces();
    if !subspaces.iter().all(|s| s.colour_marginals.is_some()) {
        return 0;
    }
    let coupling_floats = couplings(model).len() * 2 * LIGHTNESS_BINS;
    let spread_floats: usize = chroma_spreads(model).iter().map(|s| 2 * s.len()).sum();
    subspaces.len() * DIRECTIONS * TABLE_BYTES + 4 * (coupling_floats + spread_floats)
}

/// Ranges narrower than this are written as flat tables: heights in texels and factor
/// quantiles that close together are equal for every use, and steps near the subnormal range
/// lose the precision a code needs (cargo-fuzz found decoded values re-quantising to other
/// codes, so write-read-write was not a fixed point).
const FLAT_RANGE: f64 = 1e-20;

/// The precision a quantised table is held in after reading: band quantiles stay `f64`,
/// range-map heights are rounded to `f32`. The writer needs it to make write-read-write a
/// fixed point.
#[derive(Clone, Copy)]
enum Storage {
    /// 16-bit codes, held in single precision.
    Single,
    /// 16-bit codes, held in double precision.
    Double,
    /// 8-bit codes, held in single precision (the exemplar's crops: a step of a few tenths of
    /// an L* unit, below what the eye tells apart).
    Byte,
    /// 4-bit codes, two a byte (the first in the low half), held in single precision (the
    /// exemplar's L* deviations from version 9).
    Nibble,
}

impl Storage {
    /// How an exemplar's deviations with these codes are stored.
    fn of(codes: DeviationCodes) -> Self {
        match codes {
            DeviationCodes::Byte => Storage::Byte,
            DeviationCodes::Nibble => Storage::Nibble,
        }
    }

    /// Bits of a code (the exemplar's deviation code width as the file names it).
    fn bits(self) -> u8 {
        match self {
            Storage::Single | Storage::Double => 16,
            Storage::Byte => 8,
            Storage::Nibble => 4,
        }
    }

    /// A decoded value as the reader keeps it.
    fn held(self, v: f64) -> f64 {
        match self {
            Storage::Single | Storage::Byte | Storage::Nibble => f64::from(v as f32),
            Storage::Double => v,
        }
    }

    /// Bytes `count` codes take in the file.
    fn code_bytes(self, count: usize) -> usize {
        match self {
            Storage::Single | Storage::Double => 2 * count,
            Storage::Byte => count,
            Storage::Nibble => count.div_ceil(2),
        }
    }

    /// The largest code.
    fn top(self) -> u16 {
        (1u32 << self.bits())
            .saturating_sub(1)
            .min(u32::from(u16::MAX)) as u16
    }

    /// The smallest step, relative to the largest magnitude in the table, at which every
    /// decoded value re-quantises to its own code: a few of the held precision's units.
    fn resolution(self) -> f64 {
        match self {
            Storage::Single | Storage::Byte | Storage::Nibble => 2f64.powi(-22),
            Storage::Double => 2f64.powi(-36),
        }
    }
}

/// `low` (code 0) and the step per code for values from `min` to `max`, so that the decoded
/// table quantises to the same `low`, step and codes again. `low` is `min` rounded up to
/// `f32`, so the smallest value has code 0 and decodes to `low` exactly; the step is computed
/// in `f64` from it and, where the held precision rounds the top code's value, moved to the
/// step that value gives back (one or two moves in practice). Step 0 (a flat table) when the
/// range is narrower than [`FLAT_RANGE`], finer than the held precision resolves, or not
/// finite. The cargo-fuzz target btfm_payload found the step computed in `f32` from `f32`
/// ends moving by one unit on every write.
fn quantisation(min: f64, max: f64, storage: Storage) -> (f32, f32) {
    let mut low = min as f32;
    if f64::from(low) < min {
        low = low.next_up();
    }
    let codes = f64::from(storage.top());
    let step_for = |top: f64| ((top - f64::from(low)) / codes) as f32;
    let mut step = step_for(max);
    for _ in 0..8 {
        let again = step_for(storage.held(f64::from(low) + f64::from(step) * codes));
        if again == step {
            break;
        }
        step = again;
    }
    let largest = f64::from(low).abs().max(max.abs());
    let resolved = f64::from(step) > largest * storage.resolution();
    if low.is_finite() && max - f64::from(low) > FLAT_RANGE && step.is_normal() && resolved {
        (low, step)
    } else {
        (if low.is_finite() { low } else { 0.0 }, 0.0)
    }
}

/// The value of a quantised `code` (see [`write_quantised`]); one beyond single precision is an
/// error, since the writer could not store it again (cargo-fuzz found a range map decoding to
/// -inf).
fn decode(lo: f64, quantum: f64, code: u16, what: &str) -> Parse<f64> {
    let v = lo + quantum * f64::from(code);
    if (v as f32).is_finite() {
        Ok(v)
    } else {
        Err(format!("{what} {v:e} is beyond single precision"))
    }
}

/// Single-precision values (range-map heights, periods) as a file stores and reads them
/// back: what analysis keeps, so a model synthesizes the same before and after it is written
/// (the quilts that enlarge them choose patches by small differences).
pub fn as_stored(values: &[f32]) -> Vec<f32> {
    stored_as(values, Storage::Single)
}

/// The exemplar's crops and the period deviations as a file stores (8-bit codes) and reads
/// them back.
pub fn as_stored_bytes(values: &[f32]) -> Vec<f32> {
    stored_as(values, Storage::Byte)
}

/// The exemplar's L* deviations as a version 9 file stores (4-bit codes) and reads them back.
pub fn as_stored_nibbles(values: &[f32]) -> Vec<f32> {
    stored_as(values, Storage::Nibble)
}

fn stored_as(values: &[f32], storage: Storage) -> Vec<f32> {
    let wide: Vec<f64> = values.iter().map(|&v| f64::from(v)).collect();
    let (low, step, codes) = quantised_codes(&wide, storage);
    codes
        .into_iter()
        .map(|c| (f64::from(low) + f64::from(step) * f64::from(c)) as f32)
        .collect()
}

/// `low`, step and one code per value, `low + step x code` (see [`quantisation`]); rounding
/// is monotone, so a non-decreasing table stays non-decreasing.
fn quantised_codes(values: &[f64], storage: Storage) -> (f32, f32, Vec<u16>) {
    let (min, max) = values
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    let (low, step) = quantisation(min, max, storage);
    let codes = values
        .iter()
        .map(|&v| {
            if step > 0.0 {
                ((v - f64::from(low)) / f64::from(step))
                    .round()
                    .clamp(0.0, f64::from(storage.top())) as u16
            } else {
                0
            }
        })
        .collect();
    (low, step, codes)
}

/// Values as `f32` low, `f32` quantum and one code each (see [`quantised_codes`]): `u8`
/// for [`Storage::Byte`], two a byte for [`Storage::Nibble`] (an odd count's last high half
/// zero), else `u16`.
fn write_quantised(w: &mut Writer, values: &[f64], storage: Storage) {
    let (low, step, codes) = quantised_codes(values, storage);
    w.f32(f64::from(low));
    w.f32(f64::from(step));
    match storage {
        Storage::Byte => codes.iter().for_each(|&c| w.u8(c as u8)),
        Storage::Nibble => {
            for pair in codes.chunks(2) {
                w.u8((pair[0] | pair.get(1).map_or(0, |&c| c << 4)) as u8);
            }
        }
        Storage::Single | Storage::Double => codes.iter().for_each(|&c| w.u16(c)),
    }
}

/// Parses a model from bytes; `path` is only used in messages.
///
/// # Errors
/// [`ModelError::Format`] for a wrong magic, version, size or checksum, a truncated or
/// inconsistent payload, or out-of-range values. Nothing is allocated beyond what the bytes
/// can actually hold.
pub fn from_bytes(bytes: &[u8], path: &Path) -> Result<MaterialModel> {
    parse(bytes).map_err(|reason| ModelError::Format {
        path: path.to_path_buf(),
        reason,
    })
}

fn parse(bytes: &[u8]) -> Parse<MaterialModel> {
    let (version, payload) =
        envelope::open_versions(bytes, MAGIC, ".btfm", 1..=VERSION, MAX_PAYLOAD)?;
    let mut r = Reader::new(&payload);
    let code = r.u8()?;
    let kind = ModelKind::from_code(code).ok_or_else(|| format!("unknown model kind {code}"))?;
    let (width, height) = (r.u32()?, r.u32()?);
    if width == 0
        || height == 0
        || width > crate::btf::io::picture::MAX_SIDE
        || height > crate::btf::io::picture::MAX_SIDE
    {
        return Err(format!("image size {width}x{height} out of range"));
    }
    let levels = r.u8()?;
    if levels == 0 || levels > MAX_LEVELS {
        return Err(format!(
            "{levels} pyramid levels (1..={MAX_LEVELS} accepted)"
        ));
    }
    let views = DirectionSet::read_le(&mut r, "view directions")?;
    let lights = DirectionSet::read_le(&mut r, "light directions")?;
    let clusters = usize::from(r.u16()?);
    if clusters == 0 {
        return Err("no subspace models".into());
    }
    let entry = usize::from(r.u8()?);
    if entry != 1 && entry != 2 {
        return Err(format!("cluster table entry size {entry}"));
    }
    let pairs = views.len() * lights.len();
    r.ensure(pairs, entry, "cluster table")?;
    let cluster_table = (0..pairs)
        .map(|_| {
            let c = if entry == 1 {
                u16::from(r.u8()?)
            } else {
                r.u16()?
            };
            if usize::from(c) >= clusters {
                return Err(format!("cluster table names cluster {c} of {clusters}"));
            }
            Ok(c)
        })
        .collect::<Parse<Vec<u16>>>()?;
    // Every subspace needs at least its header: bound the count by the bytes left.
    r.ensure(
        clusters,
        4 + 48 + 12 * QUANTILES + usize::from(levels),
        "subspace models",
    )?;
    let mut subspaces = Vec::with_capacity(clusters);
    for _ in 0..clusters {
        let representative = (r.u16()?, r.u16()?);
        if usize::from(representative.0) >= views.len()
            || usize::from(representative.1) >= lights.len()
        {
            return Err(format!(
                "representative {representative:?} outside the direction sets"
            ));
        }
        let mean: [f64; 3] = r.f32s(3)?.try_into().expect("3");
        let b = r.f32s(9)?;
        let kl = KlBasis {
            space: ColourSpace::LinearRgb,
            mean,
            basis: std::array::from_fn(|i| std::array::from_fn(|j| b[3 * i + j])),
            variances: [0.0; 3],
        };
        let mut marginals = [[0.0; QUANTILES]; 3];
        for table in &mut marginals {
            let q = r.f32s(QUANTILES)?;
            if q.windows(2).any(|w| w[1] < w[0]) {
                return Err("quantile table is not increasing".into());
            }
            table.copy_from_slice(&q);
        }
        let level_models = kind.visit(ReadLevels {
            reader: &mut r,
            levels: usize::from(levels),
        })?;
        subspaces.push(SubspaceModel {
            representative,
            kl,
            marginals,
            marginal_grid: QuantileGrid::Uniform,
            levels: level_models,
            band_marginals: None,
            colour_marginals: None,
            lit_marginals: None,
        });
    }
    let range_map = match r.u8()? {
        0 => None,
        flag @ (1..=3) => {
            let (rows, cols) = (usize::from(r.u16()?), usize::from(r.u16()?));
            let step = usize::from(r.u16()?);
            if rows == 0 || cols == 0 || step == 0 {
                return Err("empty range map".into());
            }
            let heights = read_quantised(&mut r, rows * cols, Storage::Single, "range map height")?
                .1
                .into_iter()
                .map(|h| h as f32)
                .collect();
            let strength = if flag >= 2 {
                let n = usize::from(r.u16()?);
                if n != lights.len() {
                    return Err(format!("{n} bump strengths for {} lights", lights.len()));
                }
                let values = r.f32s(n)?;
                if let Some(bad) = values.iter().find(|k| !(0.0..=1.0).contains(*k)) {
                    return Err(format!("bump strength {bad} is outside 0..=1"));
                }
                values.into_iter().map(|k| k as f32).collect()
            } else {
                Vec::new()
            };
            Some(RangeMap {
                heights,
                rows,
                cols,
                step,
                strength,
                shadows: if flag == 3 {
                    Shadows::Cast
                } else {
                    Shadows::Attached
                },
            })
        }
        f => return Err(format!("unknown range map flag {f}")),
    };
    if version >= 2 {
        read_colour(&mut r, &mut subspaces, usize::from(levels))?;
    }
    let exemplar = if version >= 3 {
        read_colour_marginals(&mut r, &mut subspaces, version)?;
        read_exemplar(&mut r, subspaces.len(), version)?
    } else {
        None
    };
    let periodic = if version >= 4 {
        read_periodic(&mut r, subspaces.len(), range_map.is_some(), version)?
    } else {
        None
    };
    let pair_gains = if version >= 5 {
        read_pair_gains(&mut r, cluster_table.len())?
    } else {
        Vec::new()
    };
    if version >= 8 {
        read_lit_marginals(&mut r, &mut subspaces)?;
    }
    let mut light_lightness = if version >= 12 {
        read_light_lightness(&mut r, lights.len())?
    } else {
        None
    };
    let mut exemplar = exemplar;
    if version >= 15 {
        let deviations = exemplar
            .as_ref()
            .map_or(0, |e| e.lightness.basis.len().saturating_sub(1));
        let weights = read_light_weights(&mut r, lights.len(), deviations)?;
        match exemplar.as_mut() {
            Some(e) => e.light_weights = weights,
            None if weights.is_some() => return Err("light weights without an exemplar".into()),
            None => {}
        }
    }
    let mut periodic = periodic;
    if version >= 16 {
        let deviations = periodic
            .as_ref()
            .map_or(0, |p| p.periods.basis.len().saturating_sub(1));
        let weights = read_light_weights(&mut r, lights.len(), deviations)?;
        match periodic.as_mut() {
            Some(p) => p.light_weights = weights,
            None if weights.is_some() => {
                return Err("period light weights without a periodic part".into());
            }
            None => {}
        }
        read_light_spreads(&mut r, light_lightness.as_mut(), lights.len())?;
    }
    if version >= 17 {
        read_light_chroma(&mut r, light_lightness.as_mut(), lights.len())?;
    }
    r.finish()?;
    MaterialModel::new(MaterialParts {
        views,
        lights,
        width,
        height,
        cluster_table,
        subspaces,
        range_map,
        exemplar,
        periodic,
        pair_gains,
        light_lightness,
    })
    .map_err(|e| e.to_string())
}

/// Reads the version 2 tail (see [`write_colour`]) into the subspace models.
fn read_colour(r: &mut Reader, subspaces: &mut [SubspaceModel], levels: usize) -> Parse<()> {
    let space = match r.u8()? {
        0 => ColourSpace::LinearRgb,
        1 => ColourSpace::Lab,
        c => return Err(format!("unknown colour space {c}")),
    };
    let grid = match r.u8()? {
        0 => QuantileGrid::Uniform,
        1 => QuantileGrid::NormalTails,
        g => return Err(format!("unknown factor quantile grid {g}")),
    };
    let count = usize::from(r.u8()?);
    if count != 0 && count != BAND_QUANTILES {
        return Err(format!(
            "{count} band quantiles (0 or {BAND_QUANTILES} accepted)"
        ));
    }
    if count > 0 {
        r.ensure(
            subspaces.len() * levels * 3,
            8 + 2 * count,
            "band quantiles",
        )?;
    }
    for s in subspaces.iter_mut() {
        s.kl.space = space;
        s.marginal_grid = grid;
        if count == 0 {
            continue;
        }
        let mut tables = Vec::with_capacity(levels);
        for _ in 0..levels {
            let mut level: [Vec<f64>; 3] = Default::default();
            for table in &mut level {
                *table = read_table(r, count, "band quantile")?;
            }
            tables.push(level);
        }
        s.band_marginals = Some(BandMarginals { tables });
    }
    Ok(())
}

/// Reads `count` quantised values (see [`write_quantised`]), each within single precision:
/// (step, values); the codes are checked to fit before anything is allocated.
fn read_quantised(
    r: &mut Reader,
    count: usize,
    storage: Storage,
    what: &str,
) -> Parse<(f64, Vec<f64>)> {
    let (lo, quantum) = (r.f32()?, r.f32()?);
    r.ensure(storage.code_bytes(count), 1, what)?;
    let codes: Vec<u16> = match storage {
        Storage::Byte => (0..count)
            .map(|_| r.u8().map(u16::from))
            .collect::<Parse<_>>()?,
        Storage::Nibble => {
            let mut codes = Vec::with_capacity(count + 1);
            for _ in 0..count.div_ceil(2) {
                let byte = r.u8()?;
                codes.extend([u16::from(byte & 0x0f), u16::from(byte >> 4)]);
            }
            if codes.len() > count && codes.pop() != Some(0) {
                return Err(format!("{what}: the last byte's unused half is not zero"));
            }
            codes
        }
        Storage::Single | Storage::Double => (0..count).map(|_| r.u16()).collect::<Parse<_>>()?,
    };
    let values = codes
        .into_iter()
        .map(|code| decode(lo, quantum, code, what))
        .collect::<Parse<_>>()?;
    Ok((quantum, values))
}

/// Reads a quantised table of `count` values (see [`write_quantised`]): a step >= 0, finite,
/// non-decreasing.
fn read_table(r: &mut Reader, count: usize, what: &str) -> Parse<Vec<f64>> {
    let (quantum, table) = read_quantised(r, count, Storage::Double, what)?;
    if quantum < 0.0 {
        return Err(format!("negative {what} step {quantum}"));
    }
    if table.windows(2).any(|w| w[1] < w[0]) {
        return Err(format!("{what} table is not increasing"));
    }
    Ok(table)
}

/// Reads the version 3 joint colour tables, the version 7 chroma-lightness coupling and the
/// version 13 chroma spreads (see [`write_colour`]) into the subspace models.
fn read_colour_marginals(
    r: &mut Reader,
    subspaces: &mut [SubspaceModel],
    version: u16,
) -> Parse<()> {
    let count = usize::from(r.u8()?);
    let coupled = |r: &mut Reader| -> Parse<bool> {
        Ok(version >= 7 && r.u8_at_most(usize::from(count > 0), "coupling flag")? == 1)
    };
    let spread_bands = |r: &mut Reader| -> Parse<usize> {
        let most = if count > 0 { CHROMA_LEVELS } else { 0 };
        Ok(if version >= 13 {
            usize::from(r.u8_at_most(most, "chroma band count")?)
        } else {
            0
        })
    };
    if count == 0 {
        coupled(r)?;
        spread_bands(r)?;
        return Ok(());
    }
    if count != DIRECTIONS {
        return Err(format!(
            "{count} colour directions (0 or {DIRECTIONS} accepted)"
        ));
    }
    r.ensure(
        subspaces.len() * DIRECTIONS,
        TABLE_BYTES,
        "colour quantiles",
    )?;
    for s in subspaces.iter_mut() {
        let tables = (0..DIRECTIONS)
            .map(|_| read_table(r, BAND_QUANTILES, "colour quantile"))
            .collect::<Parse<Vec<_>>>()?;
        s.colour_marginals = Some(ColourMarginals {
            tables,
            coupling: None,
            chroma_spread: None,
        });
    }
    if coupled(r)? {
        let values = r.f32s(subspaces.len() * 2 * LIGHTNESS_BINS)?;
        for (s, v) in subspaces
            .iter_mut()
            .zip(values.chunks_exact(2 * LIGHTNESS_BINS))
        {
            if let Some(c) = &mut s.colour_marginals {
                c.coupling = Some(std::array::from_fn(|k| [v[2 * k], v[2 * k + 1]]));
            }
        }
    }
    let bands = spread_bands(r)?;
    if bands > 0 {
        let values = r.f32s(subspaces.len() * 2 * bands)?;
        for (s, v) in subspaces.iter_mut().zip(values.chunks_exact(2 * bands)) {
            if let Some(c) = &mut s.colour_marginals {
                c.chroma_spread = Some(v.chunks_exact(2).map(|p| [p[0], p[1]]).collect());
            }
        }
    }
    Ok(())
}

/// Reads the structure exemplar (see [`write_colour`]), if any: from version 5 a mean crop,
/// principal deviations and weights; in versions 3 and 4 one crop and a detail gain per
/// subspace, which is the same as a zero mean, that crop as the one deviation and the gains
/// as the weights (only the crops' detail is used). From version 6, flag 2 adds the chroma:
/// its block side, then its mean and deviations.
fn read_exemplar(r: &mut Reader, clusters: usize, version: u16) -> Parse<Option<Exemplar>> {
    match r.u8()? {
        0 => Ok(None),
        flag @ (1 | 2) if flag == 1 || version >= 6 => {
            let (rows, cols) = (usize::from(r.u16()?), usize::from(r.u16()?));
            if rows == 0 || cols == 0 {
                return Err("empty exemplar".into());
            }
            let deviation_codes = if version >= 9 {
                match r.u8()? {
                    8 => DeviationCodes::Byte,
                    4 => DeviationCodes::Nibble,
                    b => return Err(format!("exemplar deviations of {b} bits (8 or 4)")),
                }
            } else {
                DeviationCodes::Byte
            };
            let coarse = match (version >= 11).then(|| r.u8()).transpose()? {
                None | Some(0) => CoarseSource::Mrf,
                Some(1) => CoarseSource::Laid,
                Some(c) => return Err(format!("exemplar coarse source {c} (0 or 1)")),
            };
            let step = if version >= 14 {
                usize::from(r.u8()?)
            } else {
                1
            };
            if !(1..=MAX_EXEMPLAR_STEP).contains(&step) {
                return Err(format!(
                    "exemplar step of {step} texels (1..={MAX_EXEMPLAR_STEP})"
                ));
            }
            let lightness = if version >= 5 {
                read_principal(
                    r,
                    [rows * cols; 2],
                    clusters,
                    (
                        MAX_EXEMPLAR_COMPONENTS,
                        (Storage::Byte, Storage::of(deviation_codes)),
                    ),
                    "exemplar value",
                )?
            } else {
                let crop = read_stored(r, rows * cols, Storage::Single, "exemplar value")?;
                let gains = r.f32s(clusters)?;
                Principal {
                    basis: vec![vec![0.0; crop.len()], crop],
                    weights: gains.into_iter().map(|g| vec![g as f32]).collect(),
                }
            };
            let chroma = if flag == 2 {
                let step = usize::from(r.u8()?);
                if !(1..=MAX_CHROMA_STEP).contains(&step) {
                    return Err(format!(
                        "exemplar chroma block of {step} (1..={MAX_CHROMA_STEP})"
                    ));
                }
                let (chroma_rows, chroma_cols) = (rows.div_ceil(step), cols.div_ceil(step));
                let fields = read_principal(
                    r,
                    [2 * chroma_rows * chroma_cols; 2],
                    clusters,
                    (MAX_EXEMPLAR_COMPONENTS, (Storage::Byte, Storage::Byte)),
                    "exemplar chroma value",
                )?;
                Some(ExemplarChroma {
                    step,
                    rows: chroma_rows,
                    cols: chroma_cols,
                    fields,
                })
            } else {
                None
            };
            Ok(Some(Exemplar {
                rows,
                cols,
                step,
                lightness,
                deviation_codes,
                chroma,
                coarse,
                light_weights: None,
            }))
        }
        f => Err(format!("unknown exemplar flag {f}")),
    }
}

/// A quantised field of `count` values (see [`write_quantised`]) with a step >= 0, held in
/// single precision.
fn read_stored(r: &mut Reader, count: usize, storage: Storage, what: &str) -> Parse<Vec<f32>> {
    let (quantum, values) = read_quantised(r, count, storage, what)?;
    if quantum < 0.0 {
        return Err(format!("negative {what} step {quantum}"));
    }
    Ok(values.into_iter().map(|v| v as f32).collect())
}

/// Reads what [`write_principal`] wrote: a mean of `lens[0]` values, at most `max_deviations`
/// deviations of `lens[1]` values each, and `clusters` rows of weights.
fn read_principal(
    r: &mut Reader,
    lens: [usize; 2],
    clusters: usize,
    (max_deviations, (mean, deviation)): (usize, (Storage, Storage)),
    what: &str,
) -> Parse<Principal> {
    let deviations = usize::from(r.u8()?);
    if deviations > max_deviations {
        return Err(format!(
            "{deviations} principal deviations of the {what}s (at most {max_deviations})"
        ));
    }
    let basis = (0..=deviations)
        .map(|j| match j {
            0 => read_stored(r, lens[0], mean, what),
            _ => read_stored(r, lens[1], deviation, what),
        })
        .collect::<Parse<Vec<_>>>()?;
    r.ensure(clusters, 4 * deviations, "principal weights")?;
    let weights = (0..clusters)
        .map(|_| Ok(r.f32s(deviations)?.into_iter().map(|v| v as f32).collect()))
        .collect::<Parse<Vec<_>>>()?;
    Ok(Principal { basis, weights })
}

/// Reads the version 4 periodic part (see [`write_periodic`]), if any; the range map's
/// period is there exactly when the model has a range map.
fn read_periodic(
    r: &mut Reader,
    clusters: usize,
    with_heights: bool,
    version: u16,
) -> Parse<Option<PeriodicPart>> {
    let storage = if version >= 19 {
        PERIOD_STORAGE
    } else {
        (Storage::Single, Storage::Single)
    };
    match r.u8()? {
        0 => Ok(None),
        1 => {
            let lattice = Lattice {
                rows: r.f32()?,
                cols: r.f32()?,
            };
            let (rows, cols) = (usize::from(r.u8()?), usize::from(r.u8()?));
            if !(1..=MAX_TILE_SAMPLES).contains(&rows) || !(1..=MAX_TILE_SAMPLES).contains(&cols) {
                return Err(format!(
                    "periodic tile of {rows} x {cols} samples (1..={MAX_TILE_SAMPLES} each)"
                ));
            }
            let plane = rows * cols;
            let planes = match version {
                ..20 => 3,
                _ => match r.u8()? {
                    p @ (1 | 3) => usize::from(p),
                    p => return Err(format!("period deviations of {p} colour planes (1 or 3)")),
                },
            };
            let mut periods = read_principal(
                r,
                [3 * plane, planes * plane],
                clusters,
                (MAX_PERIOD_COMPONENTS, storage),
                "periodic tile value",
            )?;
            // A grey deviation's one plane moves all three channels.
            for d in periods.basis.iter_mut().skip(1) {
                *d = d.repeat(3 / planes);
            }
            let heights = if with_heights {
                Some(read_stored(
                    r,
                    rows * cols,
                    Storage::Single,
                    "periodic height",
                )?)
            } else {
                None
            };
            Ok(Some(PeriodicPart {
                lattice,
                rows,
                cols,
                periods,
                heights,
                light_weights: None,
            }))
        }
        f => Err(format!("unknown periodic part flag {f}")),
    }
}

/// Writes a model file atomically.
///
/// # Errors
/// The destination cannot be written.
pub fn write(model: &MaterialModel, path: &Path) -> Result<()> {
    crate::io::write_file_atomic(path, &to_bytes(model)).map_err(BtfError::from)?;
    Ok(())
}

/// Reads a model file (at most [`MAX_PAYLOAD`] + 16 bytes are read).
///
/// # Errors
/// The file cannot be read, or is not a valid model.
pub fn read(path: &Path) -> Result<MaterialModel> {
    let limit = u64::from(MAX_PAYLOAD) + envelope::OVERHEAD as u64;
    let bytes = crate::io::read_capped(path, limit).map_err(BtfError::from)?;
    from_bytes(&bytes, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bytes [`write_quantised`] writes for `values`.
    fn quantised(values: &[f64], storage: Storage) -> Vec<u8> {
        let mut w = Writer(Vec::new());
        write_quantised(&mut w, values, storage);
        w.0
    }

    /// The table those bytes decode to, held as the reader holds it.
    fn decoded(bytes: &[u8], storage: Storage) -> Vec<f64> {
        let mut r = Reader::new(bytes);
        let (lo, step) = (r.f32().unwrap(), r.f32().unwrap());
        (0..(bytes.len() - 8) / 2)
            .map(|_| storage.held(decode(lo, step, r.u16().unwrap(), "v").unwrap()))
            .collect()
    }

    #[test]
    fn quanta_too_small_for_the_held_precision_mean_a_flat_table() {
        let step = |min, max, storage| quantisation(min, max, storage).1;
        assert_eq!(quantisation(0.0, 65535.0, Storage::Double), (0.0, 1.0));
        assert_eq!(step(1.0, 1.0, Storage::Double), 0.0);
        assert_eq!(step(2.0, 1.0, Storage::Double), 0.0);
        // Heights around 1e-36 or 1e-33 apart (fuzzing's cases): written as flat.
        assert_eq!(step(6.1e-36, 7.0e-36, Storage::Single), 0.0);
        assert_eq!(step(2.37e-38, 1.55e-33, Storage::Single), 0.0);
        assert!(step(0.0, 1e-6, Storage::Single).is_normal());
        assert_eq!(step(0.0, f64::INFINITY, Storage::Double), 0.0);
        // Heights 1000 to 1000.001 in single precision cannot hold 65536 distinct codes.
        assert_eq!(step(1000.0, 1000.001, Storage::Single), 0.0);
        assert!(step(1000.0, 1000.001, Storage::Double) > 0.0);
    }

    #[test]
    fn written_tables_read_back_and_written_again_are_the_same_bytes() {
        // Offsets and spans over many magnitudes, in both held precisions (cargo-fuzz found a
        // band table whose step moved by one unit on every write).
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut uniform = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        for case in 0..20_000 {
            let storage = if case % 2 == 0 {
                Storage::Single
            } else {
                Storage::Double
            };
            let offset = (uniform() - 0.5) * 10f64.powf(uniform() * 60.0 - 30.0);
            let span = 10f64.powf(uniform() * 60.0 - 40.0);
            let mut values: Vec<f64> = (0..17).map(|_| offset + span * uniform()).collect();
            values.sort_by(f64::total_cmp);
            let once = quantised(&values, storage);
            let table = decoded(&once, storage);
            assert!(table.windows(2).all(|w| w[0] <= w[1]), "case {case}");
            let twice = quantised(&table, storage);
            assert_eq!(once, twice, "case {case}: offset {offset:e}, span {span:e}");
        }
    }

    #[test]
    fn stored_pair_gains_read_back_to_the_same_bytes() {
        for code in 0..=255u8 {
            assert_eq!(gain_code(gain_of(code)), code);
        }
        assert_eq!(gain_of(gain_code(1.0)), 1.0);
        for g in [0.013f32, 0.3, 0.97, 1.5, 7.9, 40.0] {
            let stored = as_stored_gains(&[g])[0];
            let relative = (stored / g.clamp(1.0 / 16.0, 15.7)).ln().abs();
            assert!(relative <= 0.011, "{g} -> {stored}");
        }
    }

    #[test]
    fn four_bit_codes_pack_two_a_byte_and_read_back_as_stored() {
        // An odd count: the last byte's high half is padding.
        let values: Vec<f64> = (0..7).map(|i| f64::from(i * i) - 10.0).collect();
        let mut w = Writer::default();
        write_quantised(&mut w, &values, Storage::Nibble);
        let bytes = w.0;
        assert_eq!(bytes.len(), 8 + 4, "low, step and four bytes of codes");
        assert_eq!(bytes[11] >> 4, 0, "padding");
        let (_, read) = read_quantised(&mut Reader::new(&bytes), 7, Storage::Nibble, "v").unwrap();
        let narrow: Vec<f32> = values.iter().map(|&v| v as f32).collect();
        let held: Vec<f32> = read.iter().map(|&v| v as f32).collect();
        assert_eq!(held, as_stored_nibbles(&narrow), "as analysis keeps them");
        // 16 levels over the range 36: every value within half a step (1.2) of its own.
        for (a, b) in values.iter().zip(&read) {
            assert!((a - b).abs() <= 0.6 * 36.0 / 15.0, "{a} -> {b}");
        }
        assert_eq!(read[0], -10.0, "the least value is code 0");
        assert!(
            (read[6] - 26.0).abs() < 1e-5,
            "the greatest is code 15: {}",
            read[6]
        );
        // Written again, the same bytes; a set padding half is refused.
        let mut again = Writer::default();
        let held: Vec<f64> = held.into_iter().map(f64::from).collect();
        write_quantised(&mut again, &held, Storage::Nibble);
        assert_eq!(again.0, bytes);
        let mut hostile = bytes.clone();
        hostile[11] |= 0x30;
        let e = read_quantised(&mut Reader::new(&hostile), 7, Storage::Nibble, "v").unwrap_err();
        assert!(e.contains("unused half"), "{e}");
        // Too few bytes for the codes: an error before anything is read.
        assert!(read_quantised(&mut Reader::new(&bytes[..11]), 7, Storage::Nibble, "v").is_err());
    }

    #[test]
    fn the_range_map_takes_the_bytes_counted_for_it() {
        for (strength, shadows) in [(vec![], Shadows::Attached), (vec![1.0, 0.5], Shadows::Cast)] {
            let r = RangeMap {
                heights: (0..12).map(|i| i as f32).collect(),
                rows: 3,
                cols: 4,
                step: 2,
                strength,
                shadows,
            };
            let mut w = Writer(Vec::new());
            write_range_map(&mut w, &r);
            assert_eq!(range_map_record_bytes(&r), w.0.len());
        }
    }

    /// An exemplar record: `header`, then `last` if any, no deviations and a mean of one code.
    fn exemplar_record(header: &[u8], last: Option<u8>) -> Vec<u8> {
        let mut w = Writer(header.to_vec());
        w.0.extend(last);
        w.u8(0);
        w.f32(40.0);
        w.f32(1.0);
        w.u8(10);
        w.0
    }

    #[test]
    fn an_exemplar_names_its_coarse_source_from_version_11() {
        // Flag 1, a 1 x 1 crop, 8-bit deviations, [coarse source,] ...
        let record = |coarse: Option<u8>| exemplar_record(&[1, 1, 0, 1, 0, 8], coarse);
        let read = |bytes: &[u8], version| read_exemplar(&mut Reader::new(bytes), 1, version);
        let coarse = |bytes: &[u8], version| read(bytes, version).unwrap().unwrap().coarse;
        assert_eq!(coarse(&record(None), 10), CoarseSource::Mrf);
        assert_eq!(coarse(&record(Some(0)), 11), CoarseSource::Mrf);
        assert_eq!(coarse(&record(Some(1)), 11), CoarseSource::Laid);
        let e = read(&record(Some(2)), 11).unwrap_err();
        assert!(e.contains("coarse source 2"), "{e}");
    }

    #[test]
    fn an_exemplar_names_its_step_from_version_14() {
        // Flag 1, a 1 x 1 crop, 8-bit deviations, coarse source 0, [step,] ...
        let record = |step: Option<u8>| exemplar_record(&[1, 1, 0, 1, 0, 8, 0], step);
        let read = |bytes: &[u8], version| read_exemplar(&mut Reader::new(bytes), 1, version);
        let step = |bytes: &[u8], version| read(bytes, version).unwrap().unwrap().step;
        assert_eq!(step(&record(None), 13), 1);
        assert_eq!(step(&record(Some(3)), 14), 3);
        for bad in [0, MAX_EXEMPLAR_STEP as u8 + 1] {
            let e = read(&record(Some(bad)), 14).unwrap_err();
            assert!(e.contains(&format!("exemplar step of {bad}")), "{e}");
        }
    }

    #[test]
    fn period_deviations_are_8_bit_from_version_19() {
        // One 1 x 2 period (6 values): its mean and one deviation, two subspaces' weights.
        let periods = Principal {
            basis: vec![
                vec![0.5, -1.0, 0.25, 2.0, 0.0, 1.0],
                vec![0.1, -0.2, 0.3, 0.0, 0.05, -0.1],
            ],
            weights: vec![vec![1.5], vec![-0.5]],
        };
        let record = |storage| {
            let mut w = Writer(Vec::new());
            // Flag, the lattice's periods, the samples per period.
            w.u8(1);
            w.f32(2.5);
            w.f32(3.0);
            w.u8(1);
            w.u8(2);
            write_principal(&mut w, &periods, storage);
            w.0
        };
        let read = |bytes: &[u8], version| {
            let part = read_periodic(&mut Reader::new(bytes), 2, false, version);
            part.unwrap().unwrap().periods
        };
        let (new, old) = (
            record(PERIOD_STORAGE),
            record((Storage::Single, Storage::Single)),
        );
        assert_eq!(new.len() + 6, old.len(), "a byte a deviation value saved");
        let (read_new, read_old) = (read(&new, 19), read(&old, 18));
        assert_eq!(read_new.basis[1], as_stored_bytes(&periods.basis[1]));
        assert_eq!(read_old.basis[1], as_stored(&periods.basis[1]));
        assert_ne!(read_new.basis[1], read_old.basis[1]);
        assert_eq!(read_new.basis[0], read_old.basis[0]);
        assert_eq!(read_new.weights, periods.weights);
    }

    #[test]
    fn grey_period_deviations_keep_one_plane_from_version_20() {
        // A 1 x 2 period: its mean and two deviations, stored values, two subspaces' weights.
        let grey = |a: f32, b: f32| as_stored_bytes(&[a, b]).repeat(3);
        let part = |second: Vec<f32>| PeriodicPart {
            lattice: Lattice {
                rows: 2.5,
                cols: 3.0,
            },
            rows: 1,
            cols: 2,
            periods: Principal {
                basis: vec![
                    as_stored(&[0.5, -1.0, 0.25, 2.0, 0.0, 1.0]),
                    grey(0.1, -0.2),
                    second,
                ],
                weights: vec![vec![1.5, 0.25], vec![-0.5, 2.0]],
            },
            heights: None,
            light_weights: None,
        };
        let record = |p: &PeriodicPart| {
            let mut w = Writer(Vec::new());
            write_periodic_part(&mut w, p);
            w.0
        };
        let read = |bytes: &[u8]| read_periodic(&mut Reader::new(bytes), 2, false, 20);
        let (greys, colours) = (
            part(grey(0.05, 0.3)),
            part(as_stored_bytes(&[0.05, 0.3, 0.0, 0.1, -0.1, 0.2])),
        );
        assert_eq!(
            (deviation_planes(&greys), deviation_planes(&colours)),
            (1, 3)
        );
        // A period of no samples (no file holds one) is not grey, and asking does not panic.
        let empty = PeriodicPart {
            rows: 0,
            ..greys.clone()
        };
        assert!(!empty.grey_deviations());
        let (short, long) = (record(&greys), record(&colours));
        assert_eq!(
            short.len() + 2 * 2 * 2,
            long.len(),
            "two values saved a deviation"
        );
        assert_eq!(short.len(), periodic_bytes_of(&greys));
        assert_eq!(long.len(), periodic_bytes_of(&colours));
        // Both read back exactly, the grey plane standing for all three channels.
        assert_eq!(read(&short).unwrap(), Some(greys));
        assert_eq!(read(&long).unwrap(), Some(colours));
        // Any other count of planes is refused in one line.
        let mut odd = short.clone();
        odd[11] = 2;
        let e = read(&odd).unwrap_err();
        assert!(e.contains("2 colour planes"), "{e}");
    }

    #[test]
    fn light_weights_read_back_as_stored_and_refuse_a_short_record() {
        let rows: Vec<Vec<f32>> = (0..4)
            .map(|l| vec![l as f32 * 0.25, -1.5 + 0.1 * l as f32, 3.0])
            .collect();
        let weights = LightWeights {
            view: 2,
            weights: as_stored_light_rows(&rows),
        };
        for (a, b) in weights.weights.iter().flatten().zip(rows.iter().flatten()) {
            assert!((a - b).abs() < 2e-3, "{a} stored for {b}");
        }
        let mut w = Writer(Vec::new());
        write_light_weights(&mut w, Some(&weights));
        assert_eq!(w.0.len(), 1 + 2 + 3 * (8 + 4));
        let read = read_light_weights(&mut Reader::new(&w.0), 4, 3).unwrap();
        assert_eq!(read, Some(weights));
        // One byte without; more lights or deviations than the bytes hold: refused.
        let mut none = Writer(Vec::new());
        write_light_weights(&mut none, None);
        assert_eq!(none.0, [0]);
        assert_eq!(
            read_light_weights(&mut Reader::new(&none.0), 4, 3),
            Ok(None)
        );
        for (lights, deviations) in [(5, 3), (4, 4)] {
            let e = read_light_weights(&mut Reader::new(&w.0), lights, deviations).unwrap_err();
            assert!(e.contains("light weight"), "{e}");
        }
    }

    #[test]
    fn light_lightness_tables_read_back_in_their_counted_bytes() {
        let tables = LightLightness {
            view: 3,
            tables: (0..5)
                .map(|l| LitMarginals {
                    lightness: (0..BAND_QUANTILES)
                        .map(|q| f64::from(l as u8) + 2.5 * q as f64)
                        .collect(),
                })
                .collect(),
            spreads: None,
            chroma: None,
        };
        let mut w = Writer(Vec::new());
        write_light_lightness(&mut w, Some(&tables));
        assert_eq!(w.0.len(), 1 + light_lightness_record_bytes(&tables));
        let read = read_light_lightness(&mut Reader::new(&w.0), 5)
            .unwrap()
            .unwrap();
        assert_eq!(read.view, 3);
        for (a, b) in read.tables.iter().zip(&tables.tables) {
            for (x, y) in a.lightness.iter().zip(&b.lightness) {
                assert!((x - y).abs() < 1e-3, "{x} vs {y}");
            }
        }
        // Without tables, one byte; more lights than the bytes hold: refused before reading.
        let mut none = Writer(Vec::new());
        write_light_lightness(&mut none, None);
        assert_eq!(none.0, [0]);
        assert!(
            read_light_lightness(&mut Reader::new(&none.0), 5)
                .unwrap()
                .is_none()
        );
        let e = read_light_lightness(&mut Reader::new(&w.0), 6).unwrap_err();
        assert!(e.contains("light lightness tables"), "{e}");
        let e = read_light_lightness(&mut Reader::new(&[2]), 5).unwrap_err();
        assert!(e.contains("light lightness flag"), "{e}");
    }

    #[test]
    fn light_spreads_read_back_as_stored_in_their_counted_bytes() {
        let spreads: Vec<[f32; LIGHTNESS_BANDS]> = (0..4)
            .map(|l| std::array::from_fn(|k| 0.5 + l as f32 + 2.0 * k as f32))
            .collect();
        let stored: Vec<[f32; LIGHTNESS_BANDS]> = as_stored_light_rows(&spreads)
            .into_iter()
            .map(|r| std::array::from_fn(|k| r[k]))
            .collect();
        let tables = LightLightness {
            spreads: Some(stored),
            ..zero_light_tables(4)
        };
        let without = LightLightness {
            spreads: None,
            ..tables.clone()
        };
        let rows = FlaggedRows {
            write: write_light_spreads,
            read: read_light_spreads,
            what: "light band spread",
        };
        rows.assert_round_trip(&tables, without);
    }

    /// Light lightness tables of `lights` lights, all zero, with neither spreads nor chroma.
    fn zero_light_tables(lights: usize) -> LightLightness {
        LightLightness {
            view: 0,
            tables: vec![
                LitMarginals {
                    lightness: vec![0.0; BAND_QUANTILES]
                };
                lights
            ],
            spreads: None,
            chroma: None,
        }
    }

    /// A flagged record of light rows beside the light lightness tables: its writer, its
    /// reader and the name its errors give.
    struct FlaggedRows {
        write: fn(&mut Writer, Option<&LightLightness>),
        read: fn(&mut Reader, Option<&mut LightLightness>, usize) -> Parse<()>,
        what: &'static str,
    }

    impl FlaggedRows {
        /// The record of `tables` takes the bytes `light_lightness_record_bytes` counts for
        /// it beyond `without` (the same tables without the record) and its flag, and reads
        /// back into `without` as `tables`; rows without light lightness tables, or for more
        /// lights than the bytes hold, are refused; no rows write one zero byte.
        fn assert_round_trip(&self, tables: &LightLightness, without: LightLightness) {
            let lights = tables.tables.len();
            let mut w = Writer(Vec::new());
            (self.write)(&mut w, Some(tables));
            let record =
                light_lightness_record_bytes(tables) - light_lightness_record_bytes(&without);
            assert_eq!(w.0.len(), 1 + record);
            let mut read = without;
            (self.read)(&mut Reader::new(&w.0), Some(&mut read), lights).unwrap();
            assert_eq!(&read, tables);
            let e = (self.read)(&mut Reader::new(&w.0), None, lights).unwrap_err();
            assert!(e.contains("without light lightness tables"), "{e}");
            let e = (self.read)(&mut Reader::new(&w.0), Some(&mut read), lights + 1).unwrap_err();
            assert!(e.contains(self.what), "{e}");
            let mut none = Writer(Vec::new());
            (self.write)(&mut none, None);
            assert_eq!(none.0, [0]);
        }
    }

    #[test]
    fn light_chroma_reads_back_as_stored_in_its_counted_bytes() {
        // Equal neighbours (a flat tail), steps of different sizes, and a wide range across
        // the lights, so each quantile's code rounds differently.
        let chroma: Vec<LightChroma> = (0..6)
            .map(|l| {
                let l = l as f32;
                [
                    std::array::from_fn(|k| (k.max(4) as f32 - 4.0) * (1.0 + 0.37 * l) - 0.6),
                    std::array::from_fn(|k| 10.0 + 0.9 * l + 0.013 * (k * k) as f32),
                ]
            })
            .collect();
        let stored = as_stored_light_chroma(&chroma);
        for (s, c) in stored.iter().flatten().zip(chroma.iter().flatten()) {
            assert!(s.windows(2).all(|w| w[0] <= w[1]), "{s:?}");
            for (a, b) in s.iter().zip(c) {
                // Half a code: a 255th of the quantile's range over the lights (at most 22.2).
                assert!((a - b).abs() < 0.05, "{a} vs {b}");
            }
        }
        assert_eq!(as_stored_light_chroma(&stored), stored);
        let tables = LightLightness {
            chroma: Some(stored),
            ..zero_light_tables(6)
        };
        let without = LightLightness {
            chroma: None,
            ..tables.clone()
        };
        let rows = FlaggedRows {
            write: write_light_chroma,
            read: read_light_chroma,
            what: "light chroma quantile",
        };
        rows.assert_round_trip(&tables, without);
    }

    #[test]
    fn codes_decoding_beyond_single_precision_are_errors() {
        assert_eq!(decode(1.0, 0.5, 4, "h"), Ok(3.0));
        assert!(decode(-3.0e38, -1.0e36, 65535, "h").is_err());
    }
}

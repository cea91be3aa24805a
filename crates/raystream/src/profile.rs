//! `measure --plot FILE.svg`: the lumen's diameters against arc length along the path, the
//! diameter graph a vessel-analysis workstation shows beside its curved reformation: the
//! equivalent diameter (of a circle of the section's area) as a line, broken where a section's
//! lumen is not closed, the largest and smallest calliper diameters about it, open sections as
//! crosses (their figures are of the part in the field, so they bound the lumen from below),
//! and with a graded stenosis the reference line, the lesion and the narrowed segment.
//!
//! Drawn with plotters, as SVG (`.svg`) or as pixels: a PNG (`.png`), or a DICOM Secondary
//! Capture image (`.dcm`) that joins the input's study, so that the graph can go to a PACS
//! beside the CPR. Text is laid out and, in pixels, drawn with DejaVu Sans, embedded: the
//! same layout in both, and no system fonts needed. Each series has its own colour, and the
//! legend shows colour swatches (rectangles), so every polyline of a series' colour is data:
//! the tests read the plot back through that, and hold the pixels to the SVG.

use std::path::Path;

use anyhow::{Context, Result, anyhow, bail};
use plotters::coord::Shift;
use plotters::prelude::*;
use raystream_cpu::airway::{self, Pi10};
use raystream_cpu::lumen::{Lumen, Section};
use raystream_cpu::stenosis::{self, ReferenceSource, Stenosis};

use crate::common::{DicomOut, Picture};

/// The picture's size, px.
pub const SIZE: (u32, u32) = (1000, 560);
/// Equivalent diameter (tab:blue).
pub const EQ: RGBColor = RGBColor(0x1f, 0x77, 0xb4);
/// Largest calliper diameter (tab:orange).
pub const MAX: RGBColor = RGBColor(0xff, 0x7f, 0x0e);
/// Smallest calliper diameter (tab:green).
pub const MIN: RGBColor = RGBColor(0x2c, 0xa0, 0x2c);
/// Open sections (tab:grey).
pub const OPEN: RGBColor = RGBColor(0x7f, 0x7f, 0x7f);
/// The stenosis's reference, and (faint) its narrowed segment (tab:red).
pub const REFERENCE: RGBColor = RGBColor(0xd6, 0x27, 0x28);
/// The lesion (tab:purple).
pub const LESION: RGBColor = RGBColor(0x94, 0x67, 0xbd);
/// The outer wall's largest diameter (tab:pink).
pub const WALL: RGBColor = RGBColor(0xe3, 0x77, 0xc2);

/// A diameter drawn as a line: its colour, width (px), legend and figure.
struct Quantity {
    colour: RGBColor,
    width: u32,
    label: &'static str,
    value: fn(&Lumen) -> f64,
}

/// The lines, in drawing order: D eq last, on top.
const QUANTITIES: [Quantity; 3] = [
    Quantity {
        colour: MAX,
        width: 1,
        label: "D max (largest calliper)",
        value: |l| l.max_diameter_mm,
    },
    Quantity {
        colour: MIN,
        width: 1,
        label: "D min (smallest calliper)",
        value: |l| l.min_diameter_mm,
    },
    Quantity {
        colour: EQ,
        width: 2,
        label: "D eq (circle of the area)",
        value: |l| l.equivalent_diameter_mm,
    },
];

/// Consecutive closed sections, as runs of (arc mm, lumen).
fn closed_runs(sections: &[Section]) -> Vec<Vec<(f64, &Lumen)>> {
    runs_of(sections, |s| s.lumen.as_ref().filter(|l| !l.open))
}

/// Consecutive sections of which `pick` takes something, as runs of (arc mm, it).
fn runs_of<'a, T>(
    sections: &'a [Section],
    pick: impl Fn(&'a Section) -> Option<T>,
) -> Vec<Vec<(f64, T)>> {
    let mut runs: Vec<Vec<(f64, T)>> = Vec::new();
    let mut open_run = false;
    for s in sections {
        match pick(s) {
            Some(l) => {
                if !open_run {
                    runs.push(Vec::new());
                }
                runs.last_mut().unwrap().push((s.arc_mm, l));
                open_run = true;
            }
            None => open_run = false,
        }
    }
    runs
}

/// A legend's colour swatch at (x, y).
fn swatch(c: RGBColor, alpha: f64) -> impl Fn((i32, i32)) -> Rectangle<(i32, i32)> {
    move |(x, y)| Rectangle::new([(x, y - 5), (x + 18, y + 5)], c.mix(alpha).filled())
}

/// The font every text of the plot is laid out in (registered once, before any plot).
pub fn register_font() -> Result<()> {
    static FONT: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let ok = *FONT.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular())
            .is_ok()
    });
    if !ok {
        bail!("the embedded font DejaVu Sans does not load");
    }
    Ok(())
}

/// What a plot shows.
#[derive(Clone, Copy)]
pub enum Chart<'a> {
    /// The lumen's diameters against arc length along a path `length_mm` long, with its
    /// graded stenoses.
    Profile {
        sections: &'a [Section],
        length_mm: f64,
        graded: &'a [Stenosis],
    },
    /// An airway's walls: √WA against the internal perimeter, a dot a section, and the line
    /// Pi10 is read off.
    Pi10 {
        sections: &'a [Section],
        fit: &'a Pi10,
    },
}

impl Chart<'_> {
    /// Draws the chart on `root`, `title` heading it.
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        title: &str,
    ) -> std::result::Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        match *self {
            Chart::Profile {
                sections,
                length_mm,
                graded,
            } => draw(root, title, sections, length_mm, graded),
            Chart::Pi10 { sections, fit } => draw_pi10(root, title, sections, fit),
        }
    }

    /// What it is, in words, for an error.
    fn words(&self) -> &'static str {
        match self {
            Chart::Profile { .. } => "the profile",
            Chart::Pi10 { .. } => "the Pi10 plot",
        }
    }
}

/// The chart as SVG text; `title` heads it.
pub fn svg(title: &str, chart: &Chart) -> Result<String> {
    register_font()?;
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, SIZE).into_drawing_area();
        chart.draw(&root, title).map_err(|e| anyhow!("{e}"))?;
    }
    Ok(out)
}

/// The chart as pixels: [`SIZE`], 8-bit RGB, row by row from the top left.
pub fn rgb(title: &str, chart: &Chart) -> Result<Vec<u8>> {
    register_font()?;
    let mut out = vec![0u8; 3 * SIZE.0 as usize * SIZE.1 as usize];
    {
        let root = BitMapBackend::with_buffer(&mut out, SIZE).into_drawing_area();
        chart.draw(&root, title).map_err(|e| anyhow!("{e}"))?;
    }
    Ok(out)
}

/// A chart of millimetres against millimetres.
type Axes<'a, DB> = ChartContext<
    'a,
    DB,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// `root` filled white and headed `title`, a chart over `x` and `y` on it, its axes named
/// `x_desc` and `y_desc`, its grid faint.
fn axes<'a, DB: DrawingBackend>(
    root: &'a DrawingArea<DB, Shift>,
    title: &str,
    (x, y): (std::ops::Range<f64>, std::ops::Range<f64>),
    (x_desc, y_desc): (&str, &str),
) -> std::result::Result<Axes<'a, DB>, DrawingAreaErrorKind<DB::ErrorType>> {
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(root)
        .caption(title, ("sans-serif", 20))
        .margin(14)
        .x_label_area_size(44)
        .y_label_area_size(56)
        .build_cartesian_2d(x, y)?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .x_label_formatter(&|v| format!("{v:.0}"))
        .y_label_formatter(&|v| format!("{v:.0}"))
        .light_line_style(BLACK.mix(0.05))
        .bold_line_style(BLACK.mix(0.15))
        .draw()?;
    Ok(chart)
}

/// The chart's legend, in a box at `at`.
fn legend<'a, DB: DrawingBackend + 'a>(
    chart: &mut Axes<'a, DB>,
    at: SeriesLabelPosition,
) -> std::result::Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    chart
        .configure_series_labels()
        .position(at)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.4))
        .label_font(("sans-serif", 14))
        .draw()
}

/// Draws the profile on `root`.
fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    sections: &[Section],
    length_mm: f64,
    graded: &[Stenosis],
) -> std::result::Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let runs = closed_runs(sections);
    let lumens = sections.iter().filter_map(|s| s.lumen.as_ref());
    let reference: Vec<f64> = graded
        .iter()
        .flat_map(|g| g.domain_mm.iter().filter_map(|&s| g.reference_at(s)))
        .collect();
    let walls = runs_of(sections, |s| s.wall.as_ref().map(|w| w.max_diameter_mm));
    let top = lumens
        .map(|l| l.max_diameter_mm)
        .chain(walls.iter().flatten().map(|w| w.1))
        .chain(reference.iter().copied())
        .fold(0.0, f64::max);
    // Room above the widest section for the legend; below zero only for a reference line
    // that runs there (a steep one between placed sections), so that all of it is drawn.
    let ymax = (top * 1.3).max(1.0);
    let ymin = reference.iter().copied().fold(0.0, f64::min);
    {
        let mut chart = axes(
            root,
            title,
            (0.0..length_mm.max(1e-3), ymin..ymax),
            ("arc length along the path (mm)", "diameter (mm)"),
        )?;

        // The narrowed segments first, under the lines; the first lesion's in the legend.
        for (k, n) in graded
            .iter()
            .filter_map(|g| g.narrowed.as_ref())
            .enumerate()
        {
            let pct = 100.0 * stenosis::NARROWED;
            let shade = chart.draw_series(std::iter::once(Rectangle::new(
                [(n.mm[0], ymin), (n.mm[1], ymax)],
                REFERENCE.mix(0.12).filled(),
            )))?;
            if k == 0 {
                shade
                    .label(format!(
                        "narrowed: D eq below {pct:.0} % of the reference, {:.1} mm",
                        n.mm[1] - n.mm[0]
                    ))
                    .legend(swatch(REFERENCE, 0.12));
            }
        }
        // Each quantity over every run, the first run carrying the legend's entry.
        for q in &QUANTITIES {
            for (k, run) in runs.iter().enumerate() {
                let series = if run.len() == 1 {
                    // A lone closed section: a dot, since a line needs two.
                    chart.draw_series(std::iter::once(Circle::new(
                        (run[0].0, (q.value)(run[0].1)),
                        2 + q.width,
                        q.colour.filled(),
                    )))?
                } else {
                    chart.draw_series(LineSeries::new(
                        run.iter().map(|&(s, l)| (s, (q.value)(l))),
                        q.colour.stroke_width(q.width),
                    ))?
                };
                if k == 0 {
                    series.label(q.label).legend(swatch(q.colour, 1.0));
                }
            }
        }
        // The outer wall's largest diameter, where one was found.
        for (k, run) in walls.iter().enumerate() {
            let series = if run.len() == 1 {
                chart.draw_series(std::iter::once(Circle::new(run[0], 4, WALL.filled())))?
            } else {
                chart.draw_series(LineSeries::new(run.iter().copied(), WALL.stroke_width(2)))?
            };
            if k == 0 {
                series
                    .label("outer wall D max (outer wall to outer wall)")
                    .legend(swatch(WALL, 1.0));
            }
        }
        let open: Vec<(f64, f64)> = sections
            .iter()
            .filter_map(|s| {
                let l = s.lumen.as_ref().filter(|l| l.open)?;
                Some((s.arc_mm, l.equivalent_diameter_mm))
            })
            .collect();
        if !open.is_empty() {
            chart
                .draw_series(open.iter().map(|&p| Cross::new(p, 4, OPEN.stroke_width(1))))?
                .label("open: D eq of the part in the field (a lower bound)")
                .legend(swatch(OPEN, 1.0));
        }
        // Each lesion: its reference, then its line and ring; the first's reference and each
        // lesion's grade in the legend.
        for (k, g) in graded.iter().enumerate() {
            let ends = g.domain_mm.map(|s| (s, g.reference_at(s).unwrap_or(0.0)));
            let how = match g.source {
                ReferenceSource::Fitted { .. } => "fitted",
                ReferenceSource::Placed(_) => "placed",
            };
            let dashes =
                chart.draw_series(DashedLineSeries::new(ends, 8, 5, REFERENCE.stroke_width(2)))?;
            if k == 0 {
                dashes
                    .label(format!(
                        "reference ({how}): {:.2} mm at the lesion",
                        g.at_lesion_mm
                    ))
                    .legend(swatch(REFERENCE, 1.0));
            }
            let which = if graded.len() > 1 {
                format!("lesion {}", k + 1)
            } else {
                "lesion".to_string()
            };
            chart
                .draw_series(LineSeries::new(
                    [(g.lesion_mm, ymin), (g.lesion_mm, ymax)],
                    LESION.stroke_width(1),
                ))?
                .label(format!(
                    "{which} at {:.1} mm (its D min ringed): {:.0} % by diameter ({}), {:.0} % by area",
                    g.lesion_mm,
                    g.diameter_pct,
                    stenosis::severity(g.diameter_pct),
                    g.area_pct
                ))
                .legend(swatch(LESION, 1.0));
            if let Some(l) = &sections[g.lesion].lumen {
                chart.draw_series(std::iter::once(Circle::new(
                    (g.lesion_mm, l.min_diameter_mm),
                    6,
                    LESION.stroke_width(2),
                )))?;
            }
        }
        legend(&mut chart, SeriesLabelPosition::UpperRight)?;
        root.present()?;
    }
    Ok(())
}

/// How a profile is written, by its file's name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlotFormat {
    Svg,
    Png,
    /// The PNG's pixels as a DICOM Secondary Capture image of the input's study.
    Dicom,
}

impl PlotFormat {
    /// The format `file` names (`.svg`, `.png` or `.dcm`, any case), checked before any work.
    pub fn of(file: &Path) -> Result<PlotFormat> {
        let ext = file.extension().and_then(|e| e.to_str()).unwrap_or("");
        Ok(match ext.to_ascii_lowercase().as_str() {
            "svg" => PlotFormat::Svg,
            "png" => PlotFormat::Png,
            "dcm" => PlotFormat::Dicom,
            _ => bail!(
                "--plot {}: the profile is drawn as SVG, PNG or DICOM; name the file .svg, .png or .dcm",
                file.display()
            ),
        })
    }
}

/// Writes the chart to `file`, as its name says ([`PlotFormat::of`]); a DICOM file as
/// `dicom` describes it.
pub fn write(file: &Path, title: &str, chart: &Chart, dicom: &DicomOut) -> Result<()> {
    let cannot =
        |e: anyhow::Error| anyhow!("{}: cannot draw {}: {e}", file.display(), chart.words());
    match PlotFormat::of(file)? {
        PlotFormat::Svg => {
            let text = svg(title, chart).map_err(cannot)?;
            std::fs::write(file, text).with_context(|| format!("cannot write {}", file.display()))
        }
        PlotFormat::Png | PlotFormat::Dicom => {
            let rgb = rgb(title, chart).map_err(cannot)?;
            let picture = Picture::Srgb8 {
                rgb,
                width: SIZE.0,
                height: SIZE.1,
            };
            picture.save(file, "", dicom)
        }
    }
}

/// Draws an airway's √WA against its internal perimeter on `root`: a dot a section with a
/// wall, the line fitted to them (solid over the perimeters measured, dashed where it is
/// carried to 10 mm beyond them), and Pi10 ringed on it at 10 mm.
fn draw_pi10<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    sections: &[Section],
    fit: &Pi10,
) -> std::result::Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let points = airway::pi10_points(sections);
    let [lo, hi] = fit.perimeter_range_mm;
    let line = |pi: f64| fit.intercept_mm + fit.slope * pi;
    let xmax = (hi * 1.05).max(12.0);
    let top = points
        .iter()
        .map(|p| p[1])
        .chain([line(0.0), line(xmax), fit.value_mm])
        .fold(0.0, f64::max);
    // Room above the highest for the legend.
    let ymax = (top * 1.35).max(1.0);
    let mut chart = axes(
        root,
        title,
        (0.0..xmax, 0.0..ymax),
        (
            "internal perimeter Pi (mm)",
            "square root of the wall area, √WA (mm)",
        ),
    )?;
    chart
        .draw_series(
            points
                .iter()
                .map(|&[x, y]| Circle::new((x, y), 3, EQ.filled())),
        )?
        .label(format!("a section's wall ({})", points.len()))
        .legend(swatch(EQ, 1.0));
    chart
        .draw_series(LineSeries::new(
            [lo, hi].map(|x| (x, line(x))),
            REFERENCE.stroke_width(2),
        ))?
        .label(format!(
            "√WA = {:.2} mm + {:.4} × Pi (r² {:.2})",
            fit.intercept_mm, fit.slope, fit.r2
        ))
        .legend(swatch(REFERENCE, 1.0));
    if fit.extrapolated() {
        // Carried to 10 mm: dashed, from 10 mm (so that a dash starts there) to the nearer end
        // of the perimeters measured.
        let to = if 10.0 < lo { lo } else { hi };
        chart.draw_series(DashedLineSeries::new(
            [10.0, to].map(|x| (x, line(x))),
            8,
            5,
            REFERENCE.stroke_width(2),
        ))?;
    }
    chart
        .draw_series(std::iter::once(Circle::new(
            (10.0, fit.value_mm),
            6,
            LESION.stroke_width(2),
        )))?
        .label(format!(
            "Pi10 {:.2} mm: √WA at Pi = 10 mm{}",
            fit.value_mm,
            if fit.extrapolated() {
                " (extrapolated)"
            } else {
                ""
            }
        ))
        .legend(swatch(LESION, 1.0));
    legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
    root.present()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use raystream_cpu::cpr::CprRow;
    use raystream_cpu::stenosis::StenosisOptions;
    use raystream_math::{DVec3, Vec3};
    use std::collections::HashMap;

    /// A section's figure, mm.
    type Figure = fn(&Lumen) -> f64;

    /// The profile of made-up `sections` along a path 60 mm long.
    fn profile<'a>(sections: &'a [Section], graded: &'a [Stenosis]) -> Chart<'a> {
        Chart::Profile {
            sections,
            length_mm: 60.0,
            graded,
        }
    }

    /// One SVG element: its tag and attributes.
    struct Element {
        tag: String,
        attr: HashMap<String, String>,
    }

    impl Element {
        fn get(&self, k: &str) -> &str {
            self.attr.get(k).map_or("", String::as_str)
        }
        fn num(&self, k: &str) -> f64 {
            self.get(k).parse().unwrap()
        }
        /// A polyline's points.
        fn points(&self) -> Vec<(f64, f64)> {
            self.get("points")
                .split_whitespace()
                .map(|p| {
                    let (x, y) = p.split_once(',').unwrap();
                    (x.parse().unwrap(), y.parse().unwrap())
                })
                .collect()
        }
        /// Drawn in colour `c` (its stroke, or for a filled shape its fill).
        fn is(&self, c: RGBColor) -> bool {
            let hex = format!("#{:02X}{:02X}{:02X}", c.0, c.1, c.2);
            self.get("stroke") == hex || self.get("fill") == hex
        }
    }

    /// The elements of plotters' SVG, which writes one tag a line: `<tag a="v" .../>`.
    fn elements(svg: &str) -> Vec<Element> {
        svg.lines()
            .filter_map(|line| {
                let rest = line.trim().strip_prefix('<')?;
                let (tag, mut rest) = rest.split_once(' ')?;
                let mut attr = HashMap::new();
                while let Some((k, v)) = rest.split_once("=\"") {
                    let (value, after) = v.split_once('"').unwrap();
                    attr.insert(k.trim().to_string(), value.to_string());
                    rest = after;
                }
                Some(Element {
                    tag: tag.to_string(),
                    attr,
                })
            })
            .collect()
    }

    /// `y ≈ a·x + b` by least squares over `pairs` (x, y).
    fn fit(pairs: &[(f64, f64)]) -> (f64, f64) {
        let n = pairs.len() as f64;
        let (sx, sy) = pairs
            .iter()
            .fold((0.0, 0.0), |(a, b), &(x, y)| (a + x, b + y));
        let (mx, my) = (sx / n, sy / n);
        let sxy: f64 = pairs.iter().map(|&(x, y)| (x - mx) * (y - my)).sum();
        let sxx: f64 = pairs.iter().map(|&(x, _)| (x - mx) * (x - mx)).sum();
        let a = sxy / sxx;
        (a, my - a * mx)
    }

    /// The points drawn for the next run of `len` sections: the next line's, or for a lone
    /// section the next dot's centre.
    fn drawn<'a>(
        len: usize,
        lines: &mut impl Iterator<Item = &'a &'a Element>,
        dots: &mut impl Iterator<Item = &'a &'a Element>,
    ) -> Vec<(f64, f64)> {
        if len > 1 {
            lines.next().expect("a line for each run").points()
        } else {
            let d = dots.next().expect("a dot for each lone section");
            vec![(d.num("cx"), d.num("cy"))]
        }
    }

    /// Reads the plot back and checks it against the figures it was drawn from: one affine
    /// map per axis (found from the D eq line, which must follow it within plotters' rounding
    /// to whole pixels) puts every other series' points on their figures, each run of closed
    /// sections is a line of its own (a lone one a dot), the open sections are crosses, and
    /// with a stenosis the reference, the lesion and the narrowed segment are where the grade
    /// says. Returns the number of D eq lines.
    fn check_plot(svg: &str, sections: &[Section], graded: &[Stenosis]) -> usize {
        let el = elements(svg);
        let of = |tag: &str, c: RGBColor| -> Vec<&Element> {
            el.iter().filter(|e| e.tag == tag && e.is(c)).collect()
        };
        let runs = closed_runs(sections);
        // D eq: a polyline a run of two or more, a dot a lone section, in the sections' order.
        let lines = of("polyline", EQ);
        let dots = of("circle", EQ);
        assert_eq!(lines.len(), runs.iter().filter(|r| r.len() > 1).count());
        assert_eq!(dots.len(), runs.iter().filter(|r| r.len() == 1).count());
        let (mut li, mut di) = (lines.iter(), dots.iter());
        let mut eq_pairs_x = Vec::new();
        let mut eq_pairs_y = Vec::new();
        for run in &runs {
            let pts = drawn(run.len(), &mut li, &mut di);
            assert_eq!(pts.len(), run.len());
            for (&(s, l), &(x, y)) in run.iter().zip(&pts) {
                eq_pairs_x.push((s, x));
                eq_pairs_y.push((l.equivalent_diameter_mm, y));
            }
        }
        let (ax, bx) = fit(&eq_pairs_x);
        let (ay, by) = fit(&eq_pairs_y);
        assert!(ax > 0.0 && ay < 0.0, "x grows right, y up: {ax} {ay}");
        let px = |s: f64| ax * s + bx;
        let py = |d: f64| ay * d + by;
        let near = |got: (f64, f64), want: (f64, f64), tol: f64, what: &str| {
            assert!(
                (got.0 - want.0).abs() <= tol && (got.1 - want.1).abs() <= tol,
                "{what}: drawn at {got:?}, its figures at {want:?}"
            );
        };
        // The figures each colour should show, written out here (not the drawing's table).
        let figures: [(RGBColor, &str, Figure); 3] = [
            (MAX, "D max", |l| l.max_diameter_mm),
            (MIN, "D min", |l| l.min_diameter_mm),
            (EQ, "D eq", |l| l.equivalent_diameter_mm),
        ];
        for (colour, what, value) in figures {
            let (lines, dots) = (of("polyline", colour), of("circle", colour));
            let (mut li, mut di) = (lines.iter(), dots.iter());
            for run in &runs {
                let pts = drawn(run.len(), &mut li, &mut di);
                for (&(s, l), &p) in run.iter().zip(&pts) {
                    near(p, (px(s), py(value(l))), 1.0, what);
                }
            }
        }
        // Open sections: a cross (two lines) each, about its D eq.
        let open: Vec<(f64, f64)> = sections
            .iter()
            .filter_map(|s| {
                let l = s.lumen.as_ref().filter(|l| l.open)?;
                Some((px(s.arc_mm), py(l.equivalent_diameter_mm)))
            })
            .collect();
        let crosses = of("line", OPEN);
        assert_eq!(crosses.len(), 2 * open.len());
        for (pair, &want) in crosses.chunks(2).zip(&open) {
            let mid = |e: &Element| {
                (
                    (e.num("x1") + e.num("x2")) / 2.0,
                    (e.num("y1") + e.num("y2")) / 2.0,
                )
            };
            near(mid(pair[0]), want, 1.0, "an open section's cross");
            near(mid(pair[1]), want, 1.0, "an open section's cross");
        }
        // The outer wall's D max: a line a run of sections with a wall, a dot a lone one.
        let walls = runs_of(sections, |s| s.wall.as_ref().map(|w| w.max_diameter_mm));
        let (wall_lines, wall_dots) = (of("polyline", WALL), of("circle", WALL));
        assert_eq!(
            wall_lines.len(),
            walls.iter().filter(|r| r.len() > 1).count()
        );
        assert_eq!(
            wall_dots.len(),
            walls.iter().filter(|r| r.len() == 1).count()
        );
        let (mut li, mut di) = (wall_lines.iter(), wall_dots.iter());
        for run in &walls {
            let pts = drawn(run.len(), &mut li, &mut di);
            for (&(s, d), &p) in run.iter().zip(&pts) {
                near(p, (px(s), py(d)), 1.0, "the wall's D max");
            }
        }
        if graded.is_empty() {
            assert!(of("polyline", REFERENCE).is_empty() && of("rect", REFERENCE).is_empty());
            assert!(of("polyline", LESION).is_empty());
            return lines.len();
        }
        // Each lesion's reference dashes come before its line: group them so, in order.
        let mut groups: Vec<Vec<(f64, f64)>> = Vec::new();
        let mut dashes = Vec::new();
        let mut lesion_lines = Vec::new();
        for e in el.iter().filter(|e| e.tag == "polyline") {
            if e.is(REFERENCE) {
                dashes.extend(e.points());
            } else if e.is(LESION) {
                groups.push(std::mem::take(&mut dashes));
                lesion_lines.push(e.points());
            }
        }
        assert_eq!(lesion_lines.len(), graded.len());
        let rings = of("circle", LESION);
        assert_eq!(rings.len(), graded.len());
        // The narrowed segments: faint rectangles over their arcs (the legend's swatch is the
        // one 18 px wide).
        let shades: Vec<&Element> = of("rect", REFERENCE)
            .into_iter()
            .filter(|e| e.get("opacity") == "0.12" && e.num("width") != 18.0)
            .collect();
        let mut shades = shades.iter();
        for (k, g) in graded.iter().enumerate() {
            // The reference: dashes on its line, from one end of its domain to the other.
            let dashes = &groups[k];
            assert!(!dashes.is_empty());
            for &(x, y) in dashes {
                let s = (x - bx) / ax;
                let d = g.at_lesion_mm + g.slope * (s - g.lesion_mm);
                assert!(
                    (y - py(d)).abs() <= 1.5,
                    "lesion {k}: a dash off its reference"
                );
            }
            let (x0, x1) = dashes
                .iter()
                .fold((f64::MAX, f64::MIN), |(a, b), &(x, _)| (a.min(x), b.max(x)));
            let [from, to] = g.domain_mm.map(px);
            assert!(x0 >= from - 1.0 && x0 <= from + 1.0, "{x0} {from}");
            assert!(x1 <= to + 1.0 && x1 >= to - 14.0, "{x1} {to}");
            // The lesion: a vertical line at its arc from the axis up, its D min ringed.
            let lp = &lesion_lines[k];
            for &(x, _) in lp {
                assert!((x - px(g.lesion_mm)).abs() <= 1.0);
            }
            assert!((lp[0].1 - py(0.0)).abs() <= 1.0);
            let l = sections[g.lesion].lumen.as_ref().unwrap();
            near(
                (rings[k].num("cx"), rings[k].num("cy")),
                (px(g.lesion_mm), py(l.min_diameter_mm)),
                1.0,
                "the lesion's ring",
            );
            if let Some(n) = &g.narrowed {
                let r = shades.next().expect("the narrowed segment's rectangle");
                assert!((r.num("x") - px(n.mm[0])).abs() <= 1.0);
                assert!((r.num("x") + r.num("width") - px(n.mm[1])).abs() <= 1.0);
            }
            // The legend says the grade.
            assert!(svg.contains(&format!(
                "{:.0} % by diameter ({}), {:.0} % by area",
                g.diameter_pct,
                stenosis::severity(g.diameter_pct),
                g.area_pct
            )));
        }
        assert!(shades.next().is_none(), "a shaded segment of no lesion");
        lines.len()
    }

    /// Holds the profile in pixels to its SVG (the same layout, the same font): every pixel
    /// of the D eq colour lies within 1.5 px of one of the SVG's D eq lines or dots or its
    /// legend swatch, and nearly every vertex of those lines (all but a few under the legend
    /// box or later marks) has such a pixel within 1.5 px; each lesion's line is a column of
    /// its colour where the SVG draws it; and text is drawn: dark pixels in the title's band
    /// and in the legend's box. Returns the number of D eq pixels.
    fn check_pixels(rgb: &[u8], svg: &str) -> usize {
        let (w, h) = (SIZE.0 as usize, SIZE.1 as usize);
        assert_eq!(rgb.len(), 3 * w * h);
        let px = |x: usize, y: usize| {
            let k = 3 * (y * w + x);
            RGBColor(rgb[k], rgb[k + 1], rgb[k + 2])
        };
        let el = elements(svg);
        let of = |tag: &str, c: RGBColor| -> Vec<&Element> {
            el.iter().filter(|e| e.tag == tag && e.is(c)).collect()
        };
        // The D eq marks as segments (a dot: its centre twice), and its swatch.
        let mut segments: Vec<((f64, f64), (f64, f64))> = Vec::new();
        for line in of("polyline", EQ) {
            let p = line.points();
            segments.extend(p.windows(2).map(|q| (q[0], q[1])));
        }
        for dot in of("circle", EQ) {
            let c = (dot.num("cx"), dot.num("cy"));
            segments.push((c, c));
        }
        let swatch: Vec<[f64; 4]> = of("rect", EQ)
            .iter()
            .map(|r| {
                let (x, y) = (r.num("x"), r.num("y"));
                [x, y, x + r.num("width"), y + r.num("height")]
            })
            .collect();
        assert_eq!(swatch.len(), 1);
        let off_segment = |p: (f64, f64), (a, b): ((f64, f64), (f64, f64))| {
            let (dx, dy) = (b.0 - a.0, b.1 - a.1);
            let len2 = dx * dx + dy * dy;
            let t = if len2 > 0.0 {
                (((p.0 - a.0) * dx + (p.1 - a.1) * dy) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            ((p.0 - a.0 - t * dx).powi(2) + (p.1 - a.1 - t * dy).powi(2)).sqrt()
        };
        let is_eq = |c: RGBColor| c == EQ;
        let mut count = 0;
        for y in 0..h {
            for x in 0..w {
                if !is_eq(px(x, y)) {
                    continue;
                }
                count += 1;
                let p = (x as f64, y as f64);
                let in_swatch = swatch.iter().any(|r| {
                    (r[0] - 1.0..=r[2] + 1.0).contains(&p.0)
                        && (r[1] - 1.0..=r[3] + 1.0).contains(&p.1)
                });
                // A dot is a disc of radius 4 about its centre.
                let on_mark = segments.iter().any(|&s| {
                    let r = if s.0 == s.1 { 4.0 } else { 0.0 };
                    off_segment(p, s) <= r + 1.5
                });
                assert!(
                    in_swatch || on_mark,
                    "a D eq pixel at ({x}, {y}) off every D eq mark"
                );
            }
        }
        // Nearly every vertex of the lines has its colour within 1.5 px.
        let vertices: Vec<(f64, f64)> =
            of("polyline", EQ).iter().flat_map(|l| l.points()).collect();
        let shown = vertices
            .iter()
            .filter(|&&(vx, vy)| {
                let (x0, y0) = (
                    (vx - 1.5).max(0.0).ceil() as usize,
                    (vy - 1.5).max(0.0).ceil() as usize,
                );
                (y0..=((vy + 1.5) as usize).min(h - 1))
                    .any(|y| (x0..=((vx + 1.5) as usize).min(w - 1)).any(|x| is_eq(px(x, y))))
            })
            .count();
        assert!(
            shown * 100 >= vertices.len() * 95,
            "{shown} of {} D eq vertices drawn",
            vertices.len()
        );
        // Each lesion's line: its colour in its column over most of its height.
        for line in of("polyline", LESION) {
            let p = line.points();
            let x = p[0].0.round() as usize;
            let (y0, y1) = (p[0].1.min(p[1].1) as usize, p[0].1.max(p[1].1) as usize);
            let coloured = (y0..=y1.min(h - 1))
                .filter(|&y| (x.saturating_sub(1)..=x + 1).any(|x| px(x, y) == LESION))
                .count();
            assert!(
                coloured * 10 >= (y1 - y0) * 7,
                "{coloured} of {} px",
                y1 - y0
            );
        }
        // Text: dark pixels in the title's band and in the legend's box (its border is the
        // one rectangle drawn with a 0.4 black stroke).
        let dark = |x: usize, y: usize| {
            let c = px(x, y);
            c.0 < 90 && c.1 < 90 && c.2 < 90
        };
        let title = (0..30)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .filter(|&(x, y)| dark(x, y))
            .count();
        assert!(title > 100, "{title} dark pixels in the title's band");
        let legend = el
            .iter()
            .find(|e| e.tag == "rect" && e.get("stroke") == "#000000" && e.get("opacity") == "0.4")
            .expect("the legend's box");
        let (lx, ly) = (legend.num("x") as usize, legend.num("y") as usize);
        let (lw, lh) = (legend.num("width") as usize, legend.num("height") as usize);
        let text = (ly + 2..ly + lh - 2)
            .flat_map(|y| (lx + 30..lx + lw - 2).map(move |x| (x, y)))
            .filter(|&(x, y)| dark(x, y))
            .count();
        assert!(text > 300, "{text} dark pixels in the legend");
        count
    }

    /// The profile in pixels is its SVG drawn: on the made-up sections with one lesion and
    /// with two, and without a grade.
    #[test]
    fn the_profile_in_pixels_is_its_svg() {
        let sections = made_up();
        let opts = StenosisOptions {
            lesion_mm: None,
            reference_mm: vec![],
            span_mm: 20.0,
        };
        let g = stenosis::grade(&sections, 60.0, &opts).unwrap();
        for graded in [vec![], vec![g]] {
            let text = svg("made up", &profile(&sections, &graded)).unwrap();
            let pixels = rgb("made up", &profile(&sections, &graded)).unwrap();
            assert!(check_pixels(&pixels, &text) > 500);
        }
    }

    /// Made-up sections a mm apart: closed runs broken by a section with no lumen, a lone
    /// closed section between it and two open ones, and a narrowing at 40 mm.
    fn made_up() -> Vec<Section> {
        (0..60)
            .map(|i| {
                let s = i as f64 + 0.5;
                let d = 12.0 - 0.05 * s - 6.0 * (-((s - 40.0) / 4.0).powi(2)).exp();
                match i {
                    20 | 22 => section(s, None, false),
                    23 | 24 => section(s, Some(d + 5.0), true),
                    _ => section(s, Some(d), false),
                }
            })
            .collect()
    }

    /// A section at arc `s` with D eq `d` (D max 3 mm more, D min 2 mm less), or no lumen.
    fn section(s: f64, d: Option<f64>, open: bool) -> Section {
        let row = CprRow {
            centre: Vec3::new(0.0, 0.0, s as f32),
            lateral: Vec3::X,
            normal: Vec3::Y,
        };
        let lumen = d.map(|d| Lumen {
            area_mm2: std::f64::consts::PI * d * d / 4.0,
            equivalent_diameter_mm: d,
            max_diameter_mm: d + 3.0,
            max_ends: [DVec3::ZERO; 2],
            min_diameter_mm: d - 2.0,
            min_direction: DVec3::X,
            cross_diameter_mm: d,
            centroid: DVec3::new(0.0, 0.0, s),
            offset_mm: 0.0,
            open,
        });
        Section {
            arc_mm: s,
            row,
            lumen,
            wall: None,
        }
    }

    /// Made-up sections a mm apart: closed runs broken by a section with no lumen, a lone
    /// closed section between it and two open ones, a narrowing; drawn without and with a
    /// stenosis placed on them, each point where its figures put it.
    #[test]
    fn the_profile_draws_each_figure_where_it_is() {
        let sections = made_up();
        let plain = svg("made up", &profile(&sections, &[])).unwrap();
        // Runs: 0–19, 21 (lone), 25–59.
        assert_eq!(check_plot(&plain, &sections, &[]), 2);
        let opts = StenosisOptions {
            lesion_mm: None,
            reference_mm: vec![],
            span_mm: 20.0,
        };
        let g = stenosis::grade(&sections, 60.0, &opts).unwrap();
        assert_eq!(g.lesion, 40);
        assert!(g.narrowed.is_some());
        let graded = svg("made up", &profile(&sections, std::slice::from_ref(&g))).unwrap();
        check_plot(&graded, &sections, std::slice::from_ref(&g));
        // A placed reference and no narrowed segment (the grade's own figures, changed).
        let placed = Stenosis {
            source: ReferenceSource::Placed(vec![30]),
            domain_mm: [30.5, 40.5],
            narrowed: None,
            ..g.clone()
        };
        let placed_svg = svg(
            "made up",
            &profile(&sections, std::slice::from_ref(&placed)),
        )
        .unwrap();
        check_plot(&placed_svg, &sections, std::slice::from_ref(&placed));
        assert!(placed_svg.contains("reference (placed)"));
        // Tandem lesions: a second, milder narrowing at 8 mm; both drawn, each where its
        // grade puts it.
        let tandem: Vec<Section> = sections
            .iter()
            .map(|sec| {
                let dip = 1.0 - 0.35 * (-((sec.arc_mm - 8.0) / 3.0).powi(2)).exp();
                match &sec.lumen {
                    Some(l) => section(sec.arc_mm, Some(l.equivalent_diameter_mm * dip), l.open),
                    None => section(sec.arc_mm, None, false),
                }
            })
            .collect();
        let both = stenosis::grade_lesions(&tandem, 60.0, &opts, 3).unwrap();
        assert_eq!(both.len(), 2, "{both:?}");
        assert_eq!((both[0].lesion, both[1].lesion), (40, 8));
        let tandem_svg = svg("made up", &profile(&tandem, &both)).unwrap();
        check_plot(&tandem_svg, &tandem, &both);
        assert!(tandem_svg.contains("lesion 2 at 8.5 mm"));
    }

    /// The chest CT's aorta, a section every 2 mm, as `measure --lesion 100 --span 30 --wall
    /// --plot` draws it: its closed runs, open sections at the arch, the outer wall's runs,
    /// the fitted reference and the narrowed segment where the grade puts them.
    #[test]
    fn the_aortas_profile_is_its_table() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let vol = raystream_io::load_volume(
            &root.join("../shared/data/volumes/nifti/chest_ct_stents_totalseg.nii.gz"),
            &Default::default(),
        )
        .unwrap();
        let points = raystream_io::read_curve(&root.join("examples/chest_aorta.mrk.json")).unwrap();
        let length = raystream_cpu::cpr::tortuosity(&points).unwrap().length_mm;
        let n = (length / 2.0).round() as u32;
        let opt = raystream_cpu::lumen::LumenOptions::for_volume(&vol);
        let wall = raystream_cpu::wall::WallOptions::default();
        let sections =
            raystream_cpu::lumen::measure_path(&vol, &points, n, DVec3::X, &opt, Some(&wall))
                .unwrap();
        assert!(
            sections
                .iter()
                .any(|s| s.lumen.as_ref().is_some_and(|l| l.open))
        );
        // Walls on most sections, in runs broken where none was found.
        assert!(sections.iter().filter(|s| s.wall.is_some()).count() * 10 >= sections.len() * 7);
        assert!(runs_of(&sections, |s| s.wall.as_ref()).len() >= 2);
        let opts = StenosisOptions {
            lesion_mm: Some(100.0),
            reference_mm: vec![],
            span_mm: 30.0,
        };
        let g = stenosis::grade(&sections, length, &opts).unwrap();
        assert!(g.narrowed.is_some());
        let text = svg(
            "aorta",
            &Chart::Profile {
                sections: &sections,
                length_mm: length,
                graded: std::slice::from_ref(&g),
            },
        )
        .unwrap();
        assert!(check_plot(&text, &sections, std::slice::from_ref(&g)) >= 1);
    }
}

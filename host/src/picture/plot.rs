//! Report plots with `plotters`, as SVG and PNG: error against work, error decomposition bars (side by side on a
//! log axis: L2 norms of error sources do not add, so they are never stacked), and the patch-size histogram of an
//! adaptive mesh.
//!
//! Both outputs come from the same drawing code: SVG through plotters' SVG backend (text stays text), PNG through
//! its in-memory bitmap backend, encoded with the `png` crate. Text is drawn in the font of [`super::text`].

use std::ops::Range;
use std::path::{Path, PathBuf};

use plotters::coord::ranged1d::ValueFormatter;
use plotters::coord::Shift;
use plotters::prelude::*;

use super::text::{ensure_font, FONT_FAMILY};
use super::{write_file, write_png, PictureError, RgbImage};

/// One named curve of an error-against-work plot.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    /// Name shown in the legend (e.g. the method).
    pub name: String,
    /// `(work, error)` points in drawing order; both must be finite and positive (log axes).
    pub points: Vec<(f64, f64)>,
}

/// A report plot.
#[derive(Clone, Debug, PartialEq)]
pub enum Plot {
    /// Error against work: log-log axes, one line with markers per series, legend.
    ErrorWork {
        /// Title above the plot.
        title: String,
        /// X axis label (e.g. "work units").
        x_label: String,
        /// Y axis label (e.g. "relative L2 error").
        y_label: String,
        /// The curves.
        series: Vec<Series>,
    },
    /// Grouped bars: one group per category, one bar per component side by side (e.g. error sources, each on
    /// its own), logarithmic y axis. Zero values are left out (a log axis has no zero) and counted in the legend.
    GroupedBars {
        /// Title above the plot.
        title: String,
        /// Y axis label.
        y_label: String,
        /// Group names along the x axis.
        categories: Vec<String>,
        /// `(component name, one nonnegative value per category)`; at least one value must be positive.
        components: Vec<(String, Vec<f64>)>,
    },
    /// Histogram with logarithmic bins (e.g. patch areas of an adaptive mesh): log x, count on a linear y axis.
    Histogram {
        /// Title above the plot.
        title: String,
        /// X axis label (e.g. "patch area (mm^2)").
        x_label: String,
        /// The samples; finite and positive.
        values: Vec<f64>,
        /// Number of bins, equal width in `log10(value)`.
        bins: usize,
    },
}

fn plot_err<E: std::fmt::Debug>(what: &str) -> impl Fn(E) -> PictureError + '_ {
    move |e| PictureError::Plot { what: what.to_string(), reason: format!("{e:?}") }
}

/// `lo..hi` widened to whole decades, for log axes.
fn decades(lo: f64, hi: f64) -> Range<f64> {
    let a = 10f64.powf(lo.log10().floor());
    let mut b = 10f64.powf(hi.log10().ceil());
    if b <= a {
        b = a * 10.0;
    }
    a..b
}

/// The axes and grid of a plot with a logarithmic x axis (ticks as powers of ten), in the plots' font.
fn log_x_mesh<DB: DrawingBackend, X, Y>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<X, Y>>,
    x_desc: &str,
    y_desc: &str,
    y_ticks: &dyn Fn(&f64) -> String,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>>
where
    X: Ranged<ValueType = f64> + ValueFormatter<f64>,
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .x_label_formatter(&|v| format!("{v:.0e}"))
        .y_label_formatter(y_ticks)
        .label_style((FONT_FAMILY, 14))
        .axis_desc_style((FONT_FAMILY, 16))
        .draw()
}

/// The legend box in the upper right, in the plots' font.
fn legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .label_font((FONT_FAMILY, 14))
        .draw()
}

impl Plot {
    /// The plot's title (used in error messages).
    #[must_use]
    pub fn title(&self) -> &str {
        match self {
            Plot::ErrorWork { title, .. }
            | Plot::GroupedBars { title, .. }
            | Plot::Histogram { title, .. } => title,
        }
    }

    /// Checks the data: finite, positive where an axis is logarithmic, consistent lengths, something to draw.
    ///
    /// # Errors
    /// [`PictureError::Invalid`] naming the series / component / sample that is wrong.
    pub fn validate(&self) -> Result<(), PictureError> {
        match self {
            Plot::ErrorWork { series, .. } => {
                if series.iter().all(|s| s.points.is_empty()) {
                    return Err(PictureError::invalid("error-work plot", "no points in any series"));
                }
                for s in series {
                    for (i, &(x, y)) in s.points.iter().enumerate() {
                        if !(x.is_finite() && x > 0.0 && y.is_finite() && y > 0.0) {
                            return Err(PictureError::invalid(
                                "error-work plot",
                                format!(
                                    "series {:?} point {i} ({x}, {y}) is not finite and positive",
                                    s.name
                                ),
                            ));
                        }
                    }
                }
            }
            Plot::GroupedBars { categories, components, .. } => {
                if !components.iter().any(|(_, v)| v.iter().any(|&x| x > 0.0)) {
                    return Err(PictureError::invalid("bar plot", "no positive value to draw on a log axis"));
                }
                if categories.is_empty() || components.is_empty() {
                    return Err(PictureError::invalid("bar plot", "no categories or no components"));
                }
                for (name, values) in components {
                    if values.len() != categories.len() {
                        return Err(PictureError::invalid(
                            "bar plot",
                            format!(
                                "component {name:?} has {} values for {} categories",
                                values.len(),
                                categories.len()
                            ),
                        ));
                    }
                    if let Some((i, v)) =
                        values.iter().enumerate().find(|(_, v)| !(v.is_finite() && **v >= 0.0))
                    {
                        return Err(PictureError::invalid(
                            "bar plot",
                            format!("component {name:?} value {i} ({v}) is not finite and >= 0"),
                        ));
                    }
                }
            }
            Plot::Histogram { values, bins, .. } => {
                if values.is_empty() || *bins == 0 {
                    return Err(PictureError::invalid("histogram", "no samples or zero bins"));
                }
                if let Some((i, v)) = values.iter().enumerate().find(|(_, v)| !(v.is_finite() && **v > 0.0)) {
                    return Err(PictureError::invalid(
                        "histogram",
                        format!("sample {i} ({v}) is not finite and > 0"),
                    ));
                }
            }
        }
        Ok(())
    }

    /// Histogram bin edges and counts (`bins + 1` edges, equal in `log10`); for other plots `None`.
    #[must_use]
    pub fn histogram_bins(&self) -> Option<(Vec<f64>, Vec<usize>)> {
        let Plot::Histogram { values, bins, .. } = self else { return None };
        let lo = values.iter().copied().fold(f64::INFINITY, f64::min).log10();
        let mut hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max).log10();
        if hi <= lo {
            hi = lo + 1.0;
        }
        let step = (hi - lo) / *bins as f64;
        let edges: Vec<f64> = (0..=*bins).map(|i| 10f64.powf(lo + step * i as f64)).collect();
        let mut counts = vec![0; *bins];
        for &v in values {
            let k = (((v.log10() - lo) / step).floor().max(0.0) as usize).min(bins - 1);
            counts[k] += 1;
        }
        Some((edges, counts))
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), PictureError> {
        let what = self.title();
        let e = plot_err(what);
        root.fill(&WHITE).map_err(&e)?;
        let caption = (FONT_FAMILY, 22);
        match self {
            Plot::ErrorWork { title, x_label, y_label, series } => {
                let pts = series.iter().flat_map(|s| s.points.iter());
                let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, 0f64, f64::INFINITY, 0f64);
                for &(x, y) in pts {
                    (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
                }
                let mut chart = ChartBuilder::on(root)
                    .caption(title, caption)
                    .margin(16)
                    .x_label_area_size(48)
                    .y_label_area_size(72)
                    .build_cartesian_2d(decades(x0, x1).log_scale(), decades(y0, y1).log_scale())
                    .map_err(&e)?;
                log_x_mesh(&mut chart, x_label, y_label, &|v| format!("{v:.0e}")).map_err(&e)?;
                for (i, s) in series.iter().enumerate() {
                    let colour = Palette99::pick(i).to_rgba();
                    chart
                        .draw_series(LineSeries::new(s.points.iter().copied(), colour.stroke_width(2)))
                        .map_err(&e)?
                        .label(s.name.as_str())
                        .legend(move |(x, y)| {
                            PathElement::new(vec![(x, y), (x + 24, y)], colour.stroke_width(2))
                        });
                    chart
                        .draw_series(s.points.iter().map(|&p| Circle::new(p, 3, colour.filled())))
                        .map_err(&e)?;
                }
                legend(&mut chart).map_err(&e)?;
            }
            Plot::GroupedBars { title, y_label, categories, components } => {
                let (n, m) = (categories.len(), components.len());
                let positive = components.iter().flat_map(|(_, v)| v.iter().copied()).filter(|&v| v > 0.0);
                let (lo, hi) = positive.fold((f64::INFINITY, 0f64), |(lo, hi), v| (lo.min(v), hi.max(v)));
                // Headroom above the tallest bar for the legend box (about 20 pixels per component, out of the
                // plot's height less caption, margins and axis labels), as a share of the log axis.
                let height = f64::from(root.dim_in_pixel().1);
                let share = ((m as f64 * 20.0 + 30.0) / (height - 110.0).max(1.0)).min(0.8);
                let span = (hi.log10() - lo.log10().floor()).max(1.0);
                let y = decades(lo, hi * 10f64.powf(span * share / (1.0 - share)));
                let bottom = y.start;
                let mut chart = ChartBuilder::on(root)
                    .caption(title, caption)
                    .margin(16)
                    .x_label_area_size(40)
                    .y_label_area_size(80)
                    .build_cartesian_2d(0.0..n as f64, y.log_scale())
                    .map_err(&e)?;
                chart
                    .configure_mesh()
                    .disable_x_mesh()
                    .x_labels(0)
                    .y_desc(y_label.as_str())
                    .y_label_formatter(&|v| format!("{v:.0e}"))
                    .label_style((FONT_FAMILY, 14))
                    .axis_desc_style((FONT_FAMILY, 16))
                    .draw()
                    .map_err(&e)?;
                // Group i spans [i, i + 1): its bars share the middle 80%, one slot per component.
                let slot = |i: usize, k: usize| {
                    let w = 0.8 / m as f64;
                    (i as f64 + 0.1 + w * k as f64 + 0.1 * w, i as f64 + 0.1 + w * (k + 1) as f64 - 0.1 * w)
                };
                for (k, (name, values)) in components.iter().enumerate() {
                    let colour = Palette99::pick(k).to_rgba();
                    let bars = values.iter().enumerate().filter(|(_, &v)| v > 0.0).map(|(i, &v)| {
                        let (x0, x1) = slot(i, k);
                        Rectangle::new([(x0, bottom), (x1, v)], colour.filled())
                    });
                    let zeros = values.iter().filter(|&&v| v == 0.0).count();
                    let label =
                        if zeros > 0 { format!("{name} (0 in {zeros}: not drawn)") } else { name.clone() };
                    chart
                        .draw_series(bars)
                        .map_err(&e)?
                        .label(label)
                        .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 14, y + 6)], colour.filled()));
                }
                legend(&mut chart).map_err(&e)?;
                // Group names under the x axis, centred on their groups.
                let style = TextStyle::from((FONT_FAMILY, 16).into_font()).pos(
                    plotters::style::text_anchor::Pos::new(
                        plotters::style::text_anchor::HPos::Center,
                        plotters::style::text_anchor::VPos::Top,
                    ),
                );
                for (i, name) in categories.iter().enumerate() {
                    let (px, py) = chart.backend_coord(&(i as f64 + 0.5, bottom));
                    root.draw(&Text::new(name.as_str(), (px, py + 8), style.clone())).map_err(&e)?;
                }
            }
            Plot::Histogram { title, x_label, .. } => {
                let (edges, counts) = self.histogram_bins().unwrap_or_default();
                let top = counts.iter().copied().max().unwrap_or(1).max(1) as f64 * 1.1;
                let x = decades(edges[0], edges[edges.len() - 1]);
                let mut chart = ChartBuilder::on(root)
                    .caption(title, caption)
                    .margin(16)
                    .x_label_area_size(48)
                    .y_label_area_size(64)
                    .build_cartesian_2d(x.log_scale(), 0.0..top)
                    .map_err(&e)?;
                log_x_mesh(&mut chart, x_label, "patches", &|v| format!("{v:.0}")).map_err(&e)?;
                let colour = Palette99::pick(0).to_rgba();
                chart
                    .draw_series(counts.iter().enumerate().map(|(i, &c)| {
                        Rectangle::new([(edges[i], 0.0), (edges[i + 1], c as f64)], colour.filled())
                    }))
                    .map_err(&e)?;
                chart
                    .draw_series(counts.iter().enumerate().map(|(i, &c)| {
                        Rectangle::new([(edges[i], 0.0), (edges[i + 1], c as f64)], BLACK.stroke_width(1))
                    }))
                    .map_err(&e)?;
            }
        }
        root.present().map_err(&e)?;
        Ok(())
    }

    /// Renders the plot as an SVG document of `width x height` pixels.
    ///
    /// # Errors
    /// [`PictureError::Invalid`] for bad data (see [`Plot::validate`]), [`PictureError::Font`] if the font is
    /// missing, [`PictureError::Plot`] if plotters fails.
    pub fn to_svg(&self, width: u32, height: u32) -> Result<String, PictureError> {
        self.validate()?;
        ensure_font()?;
        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, (width, height)).into_drawing_area();
            self.draw(&root)?;
        }
        Ok(svg)
    }

    /// Renders the plot as an 8-bit RGB image of `width x height` pixels.
    ///
    /// # Errors
    /// As [`Plot::to_svg`].
    pub fn to_image(&self, width: u32, height: u32) -> Result<RgbImage, PictureError> {
        self.validate()?;
        ensure_font()?;
        let mut image = RgbImage::new(width, height);
        {
            let root = BitMapBackend::with_buffer(&mut image.pixels, (width, height)).into_drawing_area();
            self.draw(&root)?;
        }
        Ok(image)
    }

    /// Writes `<stem>.svg` and `<stem>.png` at `width x height` and returns both paths.
    ///
    /// # Errors
    /// As [`Plot::to_svg`], and [`PictureError::Io`] / [`PictureError::Png`] if a file cannot be written.
    pub fn write(&self, stem: &Path, width: u32, height: u32) -> Result<(PathBuf, PathBuf), PictureError> {
        let svg_path = stem.with_extension("svg");
        let png_path = stem.with_extension("png");
        write_file(&svg_path, self.to_svg(width, height)?.as_bytes())?;
        write_png(&png_path, &self.to_image(width, height)?)?;
        Ok((svg_path, png_path))
    }
}

//! `avatarm bench chess`: the paper's chess scene played through the robot, with and without
//! the intent estimate, at each one-way delay (docs/chess.md). Every move of every trial goes to
//! CSV, the cases' summaries to JSON, and the chart (virtual grasp to real grasp, and the real
//! pieces' placement error, against the delay, intent against none) to SVG and PNG.

use std::path::{Path, PathBuf};

use avatarm_mapping::chess::{ChessCondition, ChessReport, run_chess};
use avatarm_scene::Scene;
use plotters::coord::Shift;
use plotters::prelude::*;

use super::chart::{Chart, axes, drawing_error, legend, padded, save_chart, write_table};
use crate::AppError;

/// What `bench chess` wrote.
#[derive(Debug, Clone)]
pub struct ChessOutputs {
    /// The run.
    pub report: ChessReport,
    /// Every move: `chess.csv`.
    pub csv: PathBuf,
    /// The summaries: `chess.json`.
    pub json: PathBuf,
    /// The chart.
    pub svg: PathBuf,
    /// See `svg`.
    pub png: PathBuf,
}

/// Runs the scene's `[chess]` (with `trials` trials per case when given) into `out`.
/// Errors: the scene has no `[chess]`, a trial cannot run, a file cannot be written.
pub fn run_chess_bench(
    scene: &Scene,
    trials: Option<u32>,
    delays_ms: Option<Vec<f64>>,
    progress: bool,
    out: &Path,
) -> Result<ChessOutputs, AppError> {
    let (Some(task), Some(setup)) = (&scene.file.chess, &scene.chess) else {
        return Err(AppError::flag("SCENE", "the scene has no [chess]"));
    };
    let mut task = task.clone();
    if let Some(n) = trials {
        task.trials = n;
    }
    if let Some(d) = delays_ms {
        task.delays_ms = d;
    }
    task.validate()?;
    std::fs::create_dir_all(out).map_err(|source| AppError::Io {
        path: out.to_owned(),
        action: "create",
        source,
    })?;
    let total = task.delays_ms.len() * 2 * task.trials as usize;
    let bar = crate::progress::bar(
        total as u64,
        format!("bench chess {}", scene.file.name),
        progress,
    );
    let report = run_chess(&task, setup, |done, _| bar.set_position(done as u64))?;
    bar.finish_and_clear();
    let csv = out.join("chess.csv");
    write_csv(&csv, &report.conditions)?;
    let json = out.join("chess.json");
    crate::replay::write_json(&json, &report)?;
    let svg = out.join("chess.svg");
    let png = out.join("chess.png");
    let title = format!(
        "Chess through the hidden robot: intent against none ({}, {} moves x {} trials per case)",
        scene.file.name, report.moves_per_trial, report.trials
    );
    save_chart(
        &ChessChart {
            conditions: &report.conditions,
            title: &title,
        },
        CHART_SIZE,
        &svg,
        &png,
    )?;
    Ok(ChessOutputs {
        report,
        csv,
        json,
        svg,
        png,
    })
}

const CSV_HEADER: &str = "intent,delay_ms,trial,move,notation,piece,virtual_grasp_s,real_grasp_s,\
grasp_delay_ms,grasped,place_error_mm,follow_error_mm,correct,wrong_pregrasps,touches,\
intent_lead_ms,carry_pos_rmse_mm,carry_rot_rmse_deg";

fn write_csv(path: &Path, conditions: &[ChessCondition]) -> Result<(), AppError> {
    let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.3}"));
    write_table(
        path,
        CSV_HEADER,
        conditions.iter().flat_map(|c| &c.moves).map(|m| {
            format!(
                "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
                m.intent,
                m.delay_ms,
                m.trial,
                m.index,
                m.notation,
                m.piece,
                opt(m.virtual_grasp_s),
                opt(m.real_grasp_s),
                opt(m.grasp_delay_ms),
                m.grasped.as_deref().unwrap_or(""),
                opt(m.place_error_mm),
                opt(m.follow_error_mm),
                m.correct,
                m.wrong_pregrasps,
                m.touches,
                opt(m.intent_lead_ms),
                opt(m.carry_pos_rmse_mm),
                opt(m.carry_rot_rmse_deg),
            )
        }),
    )
}

const CHART_SIZE: (u32, u32) = (1400, 620);

/// The goal of issue 48: with intent, the real grasp within 150 ms of the virtual one (median).
pub const GRASP_GOAL_MS: f64 = 150.0;
/// The goal for the real piece's placement (mm).
pub const PLACE_GOAL_MM: f64 = 5.0;

struct ChessChart<'a> {
    conditions: &'a [ChessCondition],
    title: &'a str,
}

const COLOURS: [(bool, RGBColor, &str); 2] = [
    (false, RGBColor(230, 130, 20), "no intent"),
    (true, RGBColor(30, 90, 200), "intent"),
];

impl Chart for ChessChart<'_> {
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> Result<(), AppError>
    where
        DB::ErrorType: 'static,
    {
        let err = drawing_error::<DB::ErrorType>;
        root.fill(&WHITE).map_err(err)?;
        let root = root.titled(self.title, ("sans-serif", 22)).map_err(err)?;
        let (left, right) = root.split_horizontally(CHART_SIZE.0 / 2);
        self.panel(
            &left,
            "virtual grasp to real grasp, ms (median, bar to p95)",
            GRASP_GOAL_MS,
            |c| {
                (
                    c.summary.grasp_delay_ms.median,
                    c.summary.grasp_delay_ms.p95,
                )
            },
        )?;
        self.panel(
            &right,
            "real piece from its square's centre, mm (median, bar to p95)",
            PLACE_GOAL_MM,
            |c| {
                (
                    c.summary.place_error_mm.median,
                    c.summary.place_error_mm.p95,
                )
            },
        )?;
        root.present().map_err(err)
    }
}

impl ChessChart<'_> {
    /// One figure's median and p95 against the delay, a line per case, the goal dashed; each
    /// point labelled with its case's correct moves.
    fn panel<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        y_desc: &str,
        goal: f64,
        figure: fn(&ChessCondition) -> (f64, f64),
    ) -> Result<(), AppError>
    where
        DB::ErrorType: 'static,
    {
        let err = drawing_error::<DB::ErrorType>;
        let (_, y1) = padded(
            self.conditions
                .iter()
                .flat_map(|c| {
                    let (m, p) = figure(c);
                    [m, p]
                })
                .chain([goal]),
        );
        let (x0, x1) = padded(self.conditions.iter().map(|c| c.delay_ms));
        let mut chart = axes(
            area,
            (x0.min(-10.0), x1.max(130.0)),
            (0.0, y1),
            "one-way delay between operator and robot, ms",
            y_desc,
        )?;
        chart
            .draw_series(DashedLineSeries::new(
                [(x0.min(-10.0), goal), (x1.max(130.0), goal)],
                6,
                4,
                BLACK.stroke_width(1),
            ))
            .map_err(err)?
            .label(format!("goal {goal} (issue 48)"))
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], BLACK));
        for (intent, colour, name) in COLOURS {
            let mut points: Vec<(f64, f64, f64, String)> = self
                .conditions
                .iter()
                .filter(|c| c.intent == intent)
                .map(|c| {
                    let (m, p) = figure(c);
                    let label = format!("{}/{} correct", c.summary.correct, c.summary.moves);
                    (c.delay_ms, m, p, label)
                })
                .collect();
            points.sort_by(|a, b| a.0.total_cmp(&b.0));
            let style = colour.stroke_width(2);
            chart
                .draw_series(LineSeries::new(points.iter().map(|p| (p.0, p.1)), style))
                .map_err(err)?
                .label(name)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], style));
            chart
                .draw_series(points.iter().map(|p| {
                    PathElement::new(vec![(p.0, p.1), (p.0, p.2)], colour.stroke_width(1))
                }))
                .map_err(err)?;
            chart
                .draw_series(points.iter().map(|p| {
                    EmptyElement::at((p.0, p.1))
                        + Circle::new((0, 0), 5, colour.filled())
                        + Text::new(
                            p.3.clone(),
                            (8, if intent { 8 } else { -20 }),
                            ("sans-serif", 13).into_font().color(&colour),
                        )
                }))
                .map_err(err)?;
        }
        legend(&mut chart, SeriesLabelPosition::UpperLeft)
    }
}

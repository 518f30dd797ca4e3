//! BITE runs in the formats robotics tools read: MCAP files that Foxglove,
//! Lichtblick and the `mcap` tools open without configuration, and a live
//! Foxglove WebSocket view of a running team.
//!
//! Everything is made from run-log records (the JSON lines every runtime
//! writes), through a [`Recorder`]: a simulated run hands it each record as
//! it is made, `bite log convert` reads a finished log, `bite launch` tails
//! its robots' logs. Topics (all stamped in simulated time):
//!
//! | topic | schema | what |
//! |---|---|---|
//! | `/scene` | `foxglove.SceneUpdate` | arena, obstacles, zones, objects, robots coloured by behavior, formation links |
//! | `/trails` | `foxglove.SceneUpdate` | each robot's trajectory, coloured by behavior (once a second) |
//! | `/tf` | `foxglove.FrameTransforms` | `world` → each robot |
//! | `/poses` | `foxglove.PosesInFrame` | every robot's pose in `world` |
//! | `/log` | `foxglove.Log` | one line per record, warnings for timeouts and lost teammates |
//! | `/bite/<robot>/stack` | `bite.Stack` (JSON) | the robot's behavior stack after each change |
//! | `/bite/decisions` | `bite.Decision` (JSON) | every protocol decision |
//! | `/bite/instances` | `bite.Instance` (JSON) | protocol instances started, left-out members, aborted, timed out |
//! | `/bite/informs` | `bite.Inform` (JSON) | world-model informs (Algorithm 3) |
//! | `/bite/organization` | `bite.Organization` (JSON) | lost and returning teammates, splits, rejoins, mission changes |
//! | `/bite/summary` | `bite.Summary` (JSON) | the run's summary, at its end |
//! | `/bite/events` | `bite.Record` (JSON) | every record, as logged |

pub mod legacy;
pub mod view;

use foxglove::messages as fx;
use foxglove::{Channel, Context, PartialMetadata, RawChannel, Schema};
use serde_json::{Value as J, json};
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;
pub use view::{Decision, Instance, View};

/// What can go wrong writing a run in these formats.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The Foxglove SDK refused (a file, a port).
    #[error(transparent)]
    Foxglove(#[from] foxglove::FoxgloveError),
    /// The live view's port could not be opened.
    #[error("the live view's port {port}: {reason}")]
    Listen {
        /// The port asked for (0: any).
        port: u16,
        /// Why.
        reason: std::io::Error,
    },
    /// Reading a run log (or clearing the place of an MCAP file).
    // The reason is in the message and not a `source` as well: an error
    // printed with its chain (`{:#}`) would say it twice.
    #[error("{path}: {reason}")]
    Read {
        /// The file.
        path: String,
        /// Why.
        reason: std::io::Error,
    },
    /// A line of a run log is not a JSON object.
    #[error("{path}:{line}:{column}: expected a JSON object (a run-log record): {message}")]
    Malformed {
        /// The log.
        path: String,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// What the JSON parser said.
        message: String,
    },
    /// An MCAP file that cannot be read.
    #[error("{path}: not a readable MCAP file: {message}")]
    Mcap {
        /// The file.
        path: String,
        /// What the reader said.
        message: String,
    },
}

/// The first bytes of every MCAP file.
pub const MCAP_MAGIC: &[u8] = b"\x89MCAP0\r\n";

/// The run-log records of an MCAP file written by [`Recorder`] (`--mcap`,
/// `bite log convert`): its `/bite/events` channel, in order.
pub fn read_mcap(path: &str, bytes: &[u8]) -> Result<Vec<J>, Error> {
    let bad = |message: String| Error::Mcap {
        path: path.to_string(),
        message,
    };
    let stream = mcap::MessageStream::new(bytes).map_err(|e| bad(e.to_string()))?;
    let mut out = Vec::new();
    for m in stream {
        let m = m.map_err(|e| bad(e.to_string()))?;
        if m.channel.topic != "/bite/events" {
            continue;
        }
        let rec: J = serde_json::from_slice(&m.data)
            .map_err(|e| bad(format!("a /bite/events message is not JSON: {e}")))?;
        out.push(rec);
    }
    if out.is_empty() {
        return Err(bad("no /bite/events channel (not written by BITE?)".into()));
    }
    Ok(out)
}

/// The JSON-schema channels: topic, schema name, the record kinds they
/// carry (empty: every record), and the schema.
const JSON_TOPICS: &[(&str, &str, &[&str])] = &[
    ("/bite/events", "bite.Record", &[]),
    ("/bite/decisions", "bite.Decision", &["interaction_decided"]),
    (
        "/bite/instances",
        "bite.Instance",
        &[
            "interaction_started",
            "left_out",
            "interaction_aborted",
            "interaction_timed_out",
            "preempted",
        ],
    ),
    ("/bite/informs", "bite.Inform", &["inform"]),
    (
        "/bite/organization",
        "bite.Organization",
        &[
            "member_lost",
            "member_back",
            "member_given_up",
            "split",
            "allocation_split",
            "rejoined",
            "reallocating",
            "mission_change_offered",
            "mission_changed",
            "mission_change_deferred",
            "mission_change_refused",
            "crashed",
            "restarted",
            "resumed",
            "stopped",
        ],
    ),
];

/// The JSON schema of a BITE channel.
fn schema_of(name: &str) -> J {
    let record = json!({
        "t": {"type": "number", "description": "simulated time, s"},
        "robot": {"type": "string", "description": "the robot that logged it"},
        "event": {"type": "string", "description": "what happened (docs/log-format.md)"},
    });
    let instance = json!({
        "type": "object",
        "description": "a protocol instance: the point, its team and epoch",
        "properties": {"point": {"type": "string"}, "team": {"type": "string"}, "epoch": {"type": "integer"}},
    });
    let mut props = record.as_object().cloned().unwrap_or_default();
    let (title, required, extra): (&str, Vec<&str>, J) = match name {
        "bite.Decision" => (
            "A protocol instance decided",
            vec!["t", "robot", "event", "instance", "protocol", "outcome"],
            json!({
                "instance": instance,
                "protocol": {"type": "string"},
                "outcome": {"type": "object", "description": "the decision (kind: sync, allocate or terminate)"},
                "waited_us": {"type": "integer"},
                "sent": {"type": "integer"},
                "bytes": {"type": "integer"},
                "received": {"type": "integer"},
                "timed_out": {"type": "boolean"},
            }),
        ),
        "bite.Instance" => (
            "A protocol instance's life: started, members left out, aborted, timed out",
            vec!["t", "robot", "event"],
            json!({"instance": instance, "protocol": {"type": "string"},
                   "members": {"type": "array", "items": {"type": "string"}}}),
        ),
        "bite.Inform" => (
            "A world-model inform (Algorithm 3): beliefs sent to teammates",
            vec!["t", "robot", "event", "to", "beliefs"],
            json!({"reason": {"type": "string"}, "about": {"type": ["string", "null"]},
                   "to": {"type": "array", "items": {"type": "string"}},
                   "beliefs": {"type": "array"}}),
        ),
        "bite.Organization" => (
            "Teammates lost and back, splits and rejoins, mission changes, crashes",
            vec!["t", "event"],
            json!({"member": {"type": "string"}}),
        ),
        "bite.Summary" => (
            "The run's summary (outcome, times, messages, invariants)",
            vec!["outcome"],
            json!({"outcome": {"type": "string"}, "completed": {"type": "boolean"},
                   "task_time": {"type": ["number", "null"]}, "seed": {"type": "integer"}}),
        ),
        "bite.Stack" => (
            "A robot's behavior stack, root first",
            vec!["t", "robot", "stack"],
            json!({"leaf": {"type": ["string", "null"], "description": "the behavior it runs"},
                   "depth": {"type": "integer"},
                   "stack": {"type": "array", "items": {"type": "object", "properties":
                       {"behavior": {"type": "string"}, "team": {"type": "string"}}}}}),
        ),
        _ => ("A run-log record, as logged", vec!["t", "event"], json!({})),
    };
    if name == "bite.Summary" {
        props.clear();
    }
    if let J::Object(m) = extra {
        props.extend(m);
    }
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": title,
        "type": "object",
        "properties": props,
        "required": required,
    })
}

fn json_channel(ctx: &Arc<Context>, topic: &str, schema: &str) -> Result<Arc<RawChannel>, Error> {
    let data = serde_json::to_vec(&schema_of(schema)).unwrap_or_default();
    Ok(ctx
        .channel_builder(topic)
        .message_encoding("json")
        .schema(Schema::new(schema, "jsonschema", data))
        .build_raw()?)
}

/// Nanoseconds of simulated time (negative and non-finite times are 0).
fn nanos(t: f64) -> u64 {
    if t.is_finite() && t > 0.0 {
        (t * 1e9).round() as u64
    } else {
        0
    }
}

fn stamp(t: f64) -> fx::Timestamp {
    let ns = nanos(t);
    fx::Timestamp::new(
        (ns / 1_000_000_000).min(u32::MAX as u64) as u32,
        (ns % 1_000_000_000) as u32,
    )
}

fn colour(css: &str, alpha: f64) -> fx::Color {
    let c = csscolorparser::parse(css).unwrap_or(csscolorparser::Color::new(0.6, 0.6, 0.6, 1.0));
    fx::Color {
        r: c.r as f64,
        g: c.g as f64,
        b: c.b as f64,
        a: alpha,
    }
}

fn pose(x: f64, y: f64, z: f64, yaw: f64) -> fx::Pose {
    fx::Pose {
        position: Some(fx::Vector3 { x, y, z }),
        orientation: Some(yaw_quaternion(yaw)),
    }
}

fn yaw_quaternion(yaw: f64) -> fx::Quaternion {
    fx::Quaternion {
        x: 0.0,
        y: 0.0,
        z: (yaw / 2.0).sin(),
        w: (yaw / 2.0).cos(),
    }
}

fn point(x: f64, y: f64, z: f64) -> fx::Point3 {
    fx::Point3 { x, y, z }
}

/// The frame everything is drawn in: the arena, metres, z up.
pub const WORLD_FRAME: &str = "world";

/// Turns run-log records into Foxglove messages on a [`Context`]'s
/// channels; whatever sinks the context has (an MCAP file, a WebSocket
/// server) receive them.
pub struct Recorder {
    ctx: Arc<Context>,
    view: View,
    scene: Channel<fx::SceneUpdate>,
    trails: Channel<fx::SceneUpdate>,
    tf: Channel<fx::FrameTransforms>,
    poses: Channel<fx::PosesInFrame>,
    log: Channel<fx::Log>,
    json: Vec<(Arc<RawChannel>, &'static [&'static str])>,
    summary: Arc<RawChannel>,
    stacks: BTreeMap<String, Arc<RawChannel>>,
    next_trails: f64,
    messages: u64,
}

impl Recorder {
    /// A recorder on a new context (attach sinks to [`Recorder::context`]).
    pub fn new() -> Result<Self, Error> {
        let ctx = Context::new();
        let json = JSON_TOPICS
            .iter()
            .map(|(topic, schema, kinds)| Ok((json_channel(&ctx, topic, schema)?, *kinds)))
            .collect::<Result<Vec<_>, Error>>()?;
        Ok(Recorder {
            scene: ctx.channel_builder("/scene").build(),
            trails: ctx.channel_builder("/trails").build(),
            tf: ctx.channel_builder("/tf").build(),
            poses: ctx.channel_builder("/poses").build(),
            log: ctx.channel_builder("/log").build(),
            summary: json_channel(&ctx, "/bite/summary", "bite.Summary")?,
            json,
            stacks: BTreeMap::new(),
            view: View::new(),
            next_trails: 0.0,
            messages: 0,
            ctx,
        })
    }

    /// The context whose channels the recorder logs on.
    pub fn context(&self) -> &Arc<Context> {
        &self.ctx
    }

    /// The run as the records so far show it.
    pub fn view(&self) -> &View {
        &self.view
    }

    /// Messages logged so far (on every channel).
    pub fn messages(&self) -> u64 {
        self.messages
    }

    fn raw(&mut self, ch: &RawChannel, t: f64, value: &J) {
        if let Ok(bytes) = serde_json::to_vec(value) {
            ch.log_with_meta(&bytes, PartialMetadata::with_log_time(nanos(t)));
            self.messages += 1;
        }
    }

    /// Take one run-log record: update the view and log what it shows.
    pub fn record(&mut self, rec: &J) {
        if !rec.is_object() {
            return;
        }
        let t = rec["t"].as_f64().unwrap_or(self.view.t);
        let changed = self.view.apply(rec);
        let event = rec["event"].as_str().unwrap_or("").to_string();
        let json = std::mem::take(&mut self.json);
        for (ch, kinds) in &json {
            if kinds.is_empty() || kinds.contains(&event.as_str()) {
                self.raw(ch, t, rec);
            }
        }
        self.json = json;
        if event == "run_finished"
            && let Some(s) = self.view.summary.clone()
        {
            let ch = self.summary.clone();
            self.raw(&ch, t, &s);
        }
        if event != "poses" {
            self.log_line(t, rec);
        }
        if let Some(i) = changed.stack {
            self.stack(t, i);
        }
        if changed.poses {
            self.scene(t);
        }
    }

    fn stack(&mut self, t: f64, i: usize) {
        let name = self.view.names[i].clone();
        let r = &self.view.robots[i];
        let frames: Vec<J> = (r.stack.iter())
            .map(|f| json!({"behavior": f.behavior, "team": f.team}))
            .collect();
        let msg = json!({"t": t, "robot": name, "leaf": r.stack.last().map(|f| f.behavior.clone()),
                         "depth": r.stack.len(), "stack": frames});
        let ch = match self.stacks.get(&name) {
            Some(ch) => ch.clone(),
            None => {
                let topic = format!("/bite/{name}/stack");
                let Ok(ch) = json_channel(&self.ctx, &topic, "bite.Stack") else {
                    return;
                };
                self.stacks.insert(name.clone(), ch.clone());
                ch
            }
        };
        self.raw(&ch, t, &msg);
    }

    fn log_line(&mut self, t: f64, rec: &J) {
        let event = rec["event"].as_str().unwrap_or("?");
        let level = match event {
            "interaction_timed_out"
            | "member_lost"
            | "dropped"
            | "split"
            | "allocation_split"
            | "mission_change_refused"
            | "mission_change_deferred"
            | "frame_rejected" => fx::log::Level::Warning,
            "protocol_violation" | "crashed" => fx::log::Level::Error,
            _ => fx::log::Level::Info,
        };
        let mut details = Vec::new();
        if let J::Object(m) = rec {
            for (k, v) in m {
                if matches!(k.as_str(), "t" | "robot" | "event") {
                    continue;
                }
                let v = match v {
                    J::String(s) => s.clone(),
                    other => other.to_string(),
                };
                details.push(format!("{k}={v}"));
            }
        }
        let mut message = event.replace('_', " ");
        if !details.is_empty() {
            message.push_str(": ");
            message.push_str(&details.join(" "));
        }
        let msg = fx::Log {
            timestamp: Some(stamp(t)),
            level: level as i32,
            message,
            name: rec["robot"].as_str().unwrap_or("bite").to_string(),
            file: String::new(),
            line: 0,
        };
        self.log
            .log_with_meta(&msg, PartialMetadata::with_log_time(nanos(t)));
        self.messages += 1;
    }

    /// The scene at the latest poses: robots, links, objects, the arena.
    fn scene(&mut self, t: f64) {
        let v = &self.view;
        let ts = Some(stamp(t));
        let radius = (v.layout.as_ref())
            .and_then(|l| l["robot_radius"].as_f64())
            .unwrap_or(0.15);
        let mut entities = Vec::new();
        if let Some(l) = &v.layout {
            entities.push(arena(l, ts));
            let objects = l["objects"].as_array().cloned().unwrap_or_default();
            for o in &objects {
                let name = o["name"].as_str();
                let at = name
                    .and_then(|n| v.objects.get(n).copied())
                    .or_else(|| Some([o["at"][0].as_f64()?, o["at"][1].as_f64()?]));
                if let Some([x, y]) = at {
                    let id = match name {
                        Some(n) => format!("object/{n}"),
                        None => format!("object/#{}", o["index"]),
                    };
                    entities.push(body(o, &id, x, y, ts, 0.85));
                }
            }
        }
        let mut links = Vec::new();
        let mut tfs = Vec::new();
        let mut poses = Vec::new();
        for (i, r) in v.robots.iter().enumerate() {
            let Some(p) = r.pose else { continue };
            let name = &v.names[i];
            let leaf = r.stack.last().map(|f| f.behavior.as_str());
            let c = colour(&v.behavior_colour(r.moving_as.as_deref().or(leaf)), 1.0);
            let label = match leaf {
                Some(b) => format!("{name} · {b}"),
                None if r.completed => format!("{name} · done"),
                None => name.clone(),
            };
            entities.push(fx::SceneEntity {
                timestamp: ts,
                frame_id: WORLD_FRAME.into(),
                id: format!("robot/{name}"),
                cylinders: vec![fx::CylinderPrimitive {
                    pose: Some(pose(p.x, p.y, 0.1, 0.0)),
                    size: Some(fx::Vector3 {
                        x: 2.0 * radius,
                        y: 2.0 * radius,
                        z: 0.2,
                    }),
                    bottom_scale: 1.0,
                    top_scale: 1.0,
                    color: Some(c),
                }],
                arrows: vec![fx::ArrowPrimitive {
                    pose: Some(pose(p.x, p.y, 0.22, p.heading)),
                    shaft_length: radius * 1.2,
                    shaft_diameter: radius * 0.25,
                    head_length: radius * 0.6,
                    head_diameter: radius * 0.6,
                    color: Some(colour("#222222", 1.0)),
                }],
                texts: vec![fx::TextPrimitive {
                    pose: Some(pose(p.x, p.y, 0.5, 0.0)),
                    billboard: true,
                    font_size: 14.0,
                    scale_invariant: true,
                    color: Some(colour("#111111", 1.0)),
                    text: label,
                }],
                ..Default::default()
            });
            if let Some(l) = r.link
                && let Some(lp) = v.robots.get(l).and_then(|x| x.pose)
            {
                links.push(point(p.x, p.y, 0.05));
                links.push(point(lp.x, lp.y, 0.05));
            }
            tfs.push(fx::FrameTransform {
                timestamp: ts,
                parent_frame_id: WORLD_FRAME.into(),
                child_frame_id: name.clone(),
                translation: Some(fx::Vector3 {
                    x: p.x,
                    y: p.y,
                    z: 0.0,
                }),
                rotation: Some(yaw_quaternion(p.heading)),
            });
            poses.push(pose(p.x, p.y, 0.0, p.heading));
        }
        if !links.is_empty() {
            entities.push(fx::SceneEntity {
                timestamp: ts,
                frame_id: WORLD_FRAME.into(),
                id: "links".into(),
                lines: vec![fx::LinePrimitive {
                    r#type: fx::line_primitive::Type::LineList as i32,
                    thickness: 2.0,
                    scale_invariant: true,
                    points: links,
                    color: Some(colour("#555555", 0.8)),
                    ..Default::default()
                }],
                ..Default::default()
            });
        }
        let meta = PartialMetadata::with_log_time(nanos(t));
        let deletions = if entities.iter().any(|e| e.id == "links") {
            Vec::new()
        } else {
            vec![fx::SceneEntityDeletion {
                timestamp: ts,
                r#type: fx::scene_entity_deletion::Type::MatchingId as i32,
                id: "links".into(),
            }]
        };
        self.scene.log_with_meta(
            &fx::SceneUpdate {
                deletions,
                entities,
            },
            meta,
        );
        self.tf
            .log_with_meta(&fx::FrameTransforms { transforms: tfs }, meta);
        self.poses.log_with_meta(
            &fx::PosesInFrame {
                timestamp: ts,
                frame_id: WORLD_FRAME.into(),
                poses,
            },
            meta,
        );
        self.messages += 3;
        if t + 1e-9 >= self.next_trails {
            self.next_trails = t + 1.0;
            self.trails(t);
        }
    }

    fn trails(&mut self, t: f64) {
        let v = &self.view;
        let ts = Some(stamp(t));
        let entities = (v.robots.iter().enumerate())
            .filter(|(_, r)| r.trail.len() >= 2)
            .map(|(i, r)| fx::SceneEntity {
                timestamp: ts,
                frame_id: WORLD_FRAME.into(),
                id: format!("trail/{}", v.names[i]),
                lines: vec![fx::LinePrimitive {
                    r#type: fx::line_primitive::Type::LineStrip as i32,
                    thickness: 2.0,
                    scale_invariant: true,
                    points: r.trail.iter().map(|p| point(p.x, p.y, 0.02)).collect(),
                    colors: (r.trail.iter())
                        .map(|p| colour(&v.behavior_colour(p.behavior.as_deref()), 0.9))
                        .collect(),
                    ..Default::default()
                }],
                ..Default::default()
            })
            .collect();
        self.trails.log_with_meta(
            &fx::SceneUpdate {
                deletions: Vec::new(),
                entities,
            },
            PartialMetadata::with_log_time(nanos(t)),
        );
        self.messages += 1;
    }
}

/// The arena: its walls, obstacles and zones.
fn arena(l: &J, ts: Option<fx::Timestamp>) -> fx::SceneEntity {
    let (w, h) = (
        l["arena"][0].as_f64().unwrap_or(0.0),
        l["arena"][1].as_f64().unwrap_or(0.0),
    );
    let mut lines = vec![fx::LinePrimitive {
        r#type: fx::line_primitive::Type::LineLoop as i32,
        thickness: 3.0,
        scale_invariant: true,
        points: vec![
            point(0.0, 0.0, 0.0),
            point(w, 0.0, 0.0),
            point(w, h, 0.0),
            point(0.0, h, 0.0),
        ],
        color: Some(colour("#333333", 1.0)),
        ..Default::default()
    }];
    let mut texts = Vec::new();
    for (name, z) in l["zones"].as_object().into_iter().flatten() {
        let c: Vec<f64> = (0..4).filter_map(|k| z[k].as_f64()).collect();
        if let [x0, y0, x1, y1] = c[..] {
            lines.push(fx::LinePrimitive {
                r#type: fx::line_primitive::Type::LineLoop as i32,
                thickness: 2.0,
                scale_invariant: true,
                points: vec![
                    point(x0, y0, 0.01),
                    point(x1, y0, 0.01),
                    point(x1, y1, 0.01),
                    point(x0, y1, 0.01),
                ],
                color: Some(colour("#2ca02c", 1.0)),
                ..Default::default()
            });
            texts.push(fx::TextPrimitive {
                pose: Some(pose(x0.min(x1) + 0.1, y0.max(y1) - 0.1, 0.05, 0.0)),
                billboard: true,
                font_size: 12.0,
                scale_invariant: true,
                color: Some(colour("#2ca02c", 1.0)),
                text: name.clone(),
            });
        }
    }
    let mut e = fx::SceneEntity {
        timestamp: ts,
        frame_id: WORLD_FRAME.into(),
        id: "arena".into(),
        lines,
        texts,
        ..Default::default()
    };
    for o in l["obstacles"].as_array().into_iter().flatten() {
        let (Some(x), Some(y)) = (o["at"][0].as_f64(), o["at"][1].as_f64()) else {
            continue;
        };
        let b = body(o, "", x, y, ts, 1.0);
        e.cubes.extend(b.cubes);
        e.cylinders.extend(b.cylinders);
    }
    e
}

/// An obstacle or object as a cube (box) or cylinder (disc).
fn body(o: &J, id: &str, x: f64, y: f64, ts: Option<fx::Timestamp>, alpha: f64) -> fx::SceneEntity {
    let c = colour(o["colour"].as_str().unwrap_or("#777777"), alpha);
    let angle = o["angle"].as_f64().unwrap_or(0.0);
    let size = |k: usize| o["size"][k].as_f64().unwrap_or(0.2);
    let mut e = fx::SceneEntity {
        timestamp: ts,
        frame_id: WORLD_FRAME.into(),
        id: id.into(),
        ..Default::default()
    };
    match o["shape"].as_str() {
        Some("disc") => e.cylinders.push(fx::CylinderPrimitive {
            pose: Some(pose(x, y, 0.15, angle)),
            size: Some(fx::Vector3 {
                x: 2.0 * size(0),
                y: 2.0 * size(0),
                z: 0.3,
            }),
            bottom_scale: 1.0,
            top_scale: 1.0,
            color: Some(c),
        }),
        _ => e.cubes.push(fx::CubePrimitive {
            pose: Some(pose(x, y, 0.15, angle)),
            size: Some(fx::Vector3 {
                x: size(0),
                y: size(1),
                z: 0.3,
            }),
            color: Some(c),
        }),
    }
    if let Some(n) = o["name"].as_str() {
        e.texts.push(fx::TextPrimitive {
            pose: Some(pose(x, y, 0.45, 0.0)),
            billboard: true,
            font_size: 12.0,
            scale_invariant: true,
            color: Some(colour("#333333", 1.0)),
            text: n.to_string(),
        });
    }
    e
}

/// An MCAP file being written from a recorder's channels.
pub struct McapFile {
    handle: foxglove::McapWriterHandle<std::io::BufWriter<std::fs::File>>,
}

impl McapFile {
    /// Start writing `path` (created or truncated) with every channel of
    /// `recorder`, zstd-compressed chunks.
    pub fn create(recorder: &Recorder, path: &Path) -> Result<Self, Error> {
        if path.exists() {
            std::fs::remove_file(path).map_err(|reason| Error::Read {
                path: path.display().to_string(),
                reason,
            })?;
        }
        let handle = foxglove::McapWriter::new()
            .context(recorder.context())
            .create_new_buffered_file(path)?;
        Ok(McapFile { handle })
    }

    /// Finish the file (summary, index) and close it.
    pub fn close(self) -> Result<(), Error> {
        self.handle.close()?;
        Ok(())
    }
}

/// Convert a run log (JSON lines) to an MCAP file; returns the number of
/// records read and messages written.
pub fn convert(jsonl: &Path, mcap: &Path) -> Result<(u64, u64), Error> {
    let text = std::fs::read_to_string(jsonl).map_err(|reason| Error::Read {
        path: jsonl.display().to_string(),
        reason,
    })?;
    let records = parse_records(&jsonl.display().to_string(), &text)?;
    let mut rec = Recorder::new()?;
    let file = McapFile::create(&rec, mcap)?;
    for r in &records {
        rec.record(r);
    }
    file.close()?;
    Ok((records.len() as u64, rec.messages()))
}

/// Parse the records of a run log. A last line cut short (a process killed
/// mid-write) is left out; any other line that is not a JSON object is an
/// error naming its line and column.
pub fn parse_records(path: &str, text: &str) -> Result<Vec<J>, Error> {
    let (records, mut bad) = read_records(path, text);
    if bad.is_empty() {
        Ok(records)
    } else {
        Err(bad.swap_remove(0))
    }
}

/// The records of a run log that are records, and an [`Error::Malformed`]
/// for every line that is not (in file order); a torn last line (a killed
/// process) is skipped without one (see [`read_records_torn`]).
pub fn read_records(path: &str, text: &str) -> (Vec<J>, Vec<Error>) {
    let (records, bad, _) = read_records_torn(path, text);
    (records, bad)
}

/// [`read_records`], and whether the last line was torn and skipped: a
/// last line with no newline after it that is the beginning of a record
/// cut short (the JSON ends too soon: a process killed mid-write, or a log
/// still being written). A last line that is not the beginning of a
/// record (`not json`) is malformed like any other.
pub fn read_records_torn(path: &str, text: &str) -> (Vec<J>, Vec<Error>, bool) {
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::with_capacity(lines.len());
    let mut bad = Vec::new();
    let mut torn = false;
    for (k, line) in lines.iter().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        match serde_json::from_str::<J>(line) {
            Ok(v @ J::Object(_)) => out.push(v),
            Ok(_) => bad.push(Error::Malformed {
                path: path.into(),
                line: k + 1,
                column: 1,
                message: "a JSON value that is not an object".into(),
            }),
            Err(e) if e.is_eof() && k + 1 == lines.len() && !text.ends_with('\n') => {
                torn = true;
            }
            Err(e) => bad.push(Error::Malformed {
                path: path.into(),
                line: k + 1,
                column: e.column(),
                message: e.to_string(),
            }),
        }
    }
    (out, bad, torn)
}

/// Merge the logs of a team (each robot's, the simulator server's) into one
/// stream in time order (stable: records at the same time keep their
/// file order, files in the order given).
pub fn merge(logs: Vec<Vec<J>>) -> Vec<J> {
    let mut all: Vec<(f64, usize, usize, J)> = Vec::new();
    for (f, log) in logs.into_iter().enumerate() {
        for (k, r) in log.into_iter().enumerate() {
            let t = r["t"].as_f64().unwrap_or(0.0);
            all.push((t, f, k, r));
        }
    }
    all.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    all.into_iter().map(|x| x.3).collect()
}

/// A live Foxglove WebSocket server on 127.0.0.1 showing a recorder's
/// channels: the SDK's server on a private port behind
/// [`legacy::Front`], which lets in viewers asking by the subprotocol's
/// older name too.
pub struct Live {
    handle: foxglove::WebSocketServerHandle,
    front: legacy::Front,
}

impl Live {
    /// Serve `recorder`'s channels on 127.0.0.1:`port` (0: any free port),
    /// announcing simulated time.
    pub fn start(recorder: &Recorder, port: u16, name: &str) -> Result<Self, Error> {
        let handle = foxglove::WebSocketServer::new()
            .name(name)
            .context(recorder.context())
            .bind("127.0.0.1", 0)
            .capabilities([foxglove::websocket::Capability::Time])
            .start_blocking()?;
        let inner = std::net::SocketAddr::from(([127, 0, 0, 1], handle.port()));
        match legacy::Front::start(port, inner) {
            Ok(front) => Ok(Live { handle, front }),
            Err(reason) => {
                let _ = handle.stop();
                Err(Error::Listen { port, reason })
            }
        }
    }

    /// The port viewers connect to.
    pub fn port(&self) -> u16 {
        self.front.port()
    }

    /// Clients connected now.
    pub fn clients(&self) -> usize {
        self.handle.client_count()
    }

    /// Tell clients the simulated time.
    pub fn time(&self, t: f64) {
        self.handle.broadcast_time(nanos(t));
    }

    /// Stop serving.
    pub fn stop(self) {
        self.front.stop();
        let _ = self.handle.stop();
    }
}

//! The bridge's TOML file: the ROS 2 domain, the graph's domain and prefix, the topics read into the graph (with
//! their target node, QoS and rate), and what is published out of it (RT edges on `/tf` and `/tf_static`, image and
//! laser attributes as `sensor_msgs` messages). Unknown fields are refused, and every check says which entry is wrong.

use std::path::Path;

use serde::Deserialize;

use crate::qos::QosProfile;

/// The message types the bridge reads and writes, by their ROS 2 names.
pub const IN_TYPES: &[&str] = &["sensor_msgs/msg/LaserScan", "sensor_msgs/msg/Image", "tf2_msgs/msg/TFMessage"];

/// A bridge file that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file cannot be read.
    #[error("cannot read {path}: {error}")]
    Read {
        /// The file.
        path: String,
        /// Why.
        error: std::io::Error,
    },
    /// The text is not a valid bridge file.
    #[error("{path}: {error}")]
    Parse {
        /// The file.
        path: String,
        /// The TOML error, with its line and column.
        error: Box<toml::de::Error>,
    },
    /// A field has a value the bridge cannot use.
    #[error("{path}: {field}: {what}")]
    Invalid {
        /// The file.
        path: String,
        /// Which field (`in[2].type`).
        field: String,
        /// What is wrong.
        what: String,
    },
}

/// The whole file.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BridgeConfig {
    /// The ROS 2 domain (`ROS_DOMAIN_ID`) the bridge's ROS 2 side joins.
    pub ros_domain: u16,
    /// The DSR domain of the graph's agents.
    #[serde(default)]
    pub dsr_domain: u16,
    /// The graph's topic prefix.
    #[serde(default = "default_prefix")]
    pub dsr_prefix: String,
    /// The bridge agent's id in the graph.
    #[serde(default = "default_agent_id")]
    pub agent_id: u32,
    /// Topics read into the graph.
    #[serde(default, rename = "in")]
    pub inputs: Vec<InTopic>,
    /// RT edges published as TF, if present.
    #[serde(default)]
    pub tf_out: Option<TfOut>,
    /// Image attributes published as `sensor_msgs/msg/Image`.
    #[serde(default)]
    pub image_out: Vec<AttrOut>,
    /// Laser attributes published as `sensor_msgs/msg/LaserScan`.
    #[serde(default)]
    pub laser_out: Vec<LaserOut>,
}

fn default_prefix() -> String {
    "dsr".into()
}

fn default_agent_id() -> u32 {
    200
}

/// One ROS 2 topic read into the graph.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct InTopic {
    /// The ROS 2 topic (`/scan`); its DDS topic is `rt/scan`.
    pub topic: String,
    /// The ROS 2 type (`sensor_msgs/msg/LaserScan`); its DDS type is `sensor_msgs::msg::dds_::LaserScan_`.
    #[serde(rename = "type")]
    pub type_name: String,
    /// The node the samples are written to (default: the topic's name, as `replay` names it). TF messages write
    /// RT edges between frame nodes, whatever this says.
    #[serde(default)]
    pub node: Option<String>,
    /// The QoS profile (`sensor`, `default`, `static`; default `sensor`).
    #[serde(default = "sensor")]
    pub qos: QosProfile,
    /// At most this many samples per second are written (others are counted and skipped); absent: every sample.
    #[serde(default)]
    pub max_rate_hz: Option<f64>,
}

fn sensor() -> QosProfile {
    QosProfile::Sensor
}

fn default_qos() -> QosProfile {
    QosProfile::Default
}

/// RT edges out as TF.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TfOut {
    /// How often `/tf` is published (every non-static RT edge, stamped now).
    pub rate_hz: f64,
    /// Child node names whose RT edge is static: published on `/tf_static` (transient local), once and again
    /// whenever one of them changes.
    #[serde(default)]
    pub static_frames: Vec<String>,
}

/// An image node published as `sensor_msgs/msg/Image`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct AttrOut {
    /// The node holding `cam_rgb` and its size attributes.
    pub node: String,
    /// The ROS 2 topic.
    pub topic: String,
    /// At most this many messages per second (a message is sent only when the attribute changed).
    pub rate_hz: f64,
    /// The QoS profile (default `default`: reliable, as `image_transport` publishes).
    #[serde(default = "default_qos")]
    pub qos: QosProfile,
}

/// A laser node published as `sensor_msgs/msg/LaserScan`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LaserOut {
    /// The node holding `laser_dists` and `laser_angles`.
    pub node: String,
    /// The ROS 2 topic.
    pub topic: String,
    /// At most this many messages per second (a message is sent only when the attribute changed).
    pub rate_hz: f64,
    /// The QoS profile (default `sensor`, as laser drivers publish).
    #[serde(default = "sensor")]
    pub qos: QosProfile,
    /// `range_min` of the messages, m (the graph does not hold it).
    #[serde(default)]
    pub range_min_m: f32,
    /// `range_max` of the messages, m.
    #[serde(default = "default_range_max")]
    pub range_max_m: f32,
}

fn default_range_max() -> f32 {
    100.0
}

impl BridgeConfig {
    /// Reads and checks a bridge file.
    ///
    /// # Errors
    /// [`ConfigError`] naming the file and the field.
    pub fn load(path: &Path) -> Result<BridgeConfig, ConfigError> {
        let shown = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|error| ConfigError::Read { path: shown.clone(), error })?;
        BridgeConfig::parse(&text, &shown)
    }

    /// Parses and checks the text of a bridge file (`path` is only used in errors).
    ///
    /// # Errors
    /// [`ConfigError`] naming the field.
    pub fn parse(text: &str, path: &str) -> Result<BridgeConfig, ConfigError> {
        let config: BridgeConfig =
            toml::from_str(text).map_err(|error| ConfigError::Parse { path: path.into(), error: Box::new(error) })?;
        config.check().map_err(|(field, what)| ConfigError::Invalid { path: path.into(), field, what })?;
        Ok(config)
    }

    fn check(&self) -> Result<(), (String, String)> {
        if self.ros_domain > 232 {
            return Err(("ros_domain".into(), format!("{} is over 232", self.ros_domain)));
        }
        if self.dsr_domain > 232 {
            return Err(("dsr_domain".into(), format!("{} is over 232", self.dsr_domain)));
        }
        for (i, input) in self.inputs.iter().enumerate() {
            let field = |name: &str| format!("in[{i}].{name}");
            check_topic(&input.topic).map_err(|what| (field("topic"), what))?;
            if !IN_TYPES.contains(&input.type_name.as_str()) {
                return Err((field("type"), format!("{:?} is not one of {IN_TYPES:?}", input.type_name)));
            }
            if let Some(rate) = input.max_rate_hz {
                check_rate(rate).map_err(|what| (field("max_rate_hz"), what))?;
            }
            if self.inputs[..i].iter().any(|earlier| earlier.topic == input.topic) {
                return Err((field("topic"), format!("{} is read twice", input.topic)));
            }
        }
        self.check_outputs()
    }

    /// The output entries, and that no topic is written twice or both read and written (the bridge would read
    /// back what it writes: `/tf` both ways echoes every transform).
    fn check_outputs(&self) -> Result<(), (String, String)> {
        let mut written: Vec<(String, &str)> = Vec::new();
        if let Some(tf) = &self.tf_out {
            check_rate(tf.rate_hz).map_err(|what| ("tf_out.rate_hz".to_owned(), what))?;
            written.extend([("tf_out".to_owned(), "/tf"), ("tf_out".to_owned(), "/tf_static")]);
        }
        for (i, out) in self.image_out.iter().enumerate() {
            check_topic(&out.topic).map_err(|what| (format!("image_out[{i}].topic"), what))?;
            check_rate(out.rate_hz).map_err(|what| (format!("image_out[{i}].rate_hz"), what))?;
            written.push((format!("image_out[{i}]"), &out.topic));
        }
        for (i, out) in self.laser_out.iter().enumerate() {
            check_topic(&out.topic).map_err(|what| (format!("laser_out[{i}].topic"), what))?;
            check_rate(out.rate_hz).map_err(|what| (format!("laser_out[{i}].rate_hz"), what))?;
            written.push((format!("laser_out[{i}]"), &out.topic));
        }
        for (j, (entry, topic)) in written.iter().enumerate() {
            if let Some((earlier, _)) = written[..j].iter().find(|(_, other)| other == topic) {
                return Err((format!("{entry}.topic"), format!("{topic} is also written by {earlier}")));
            }
            if let Some(i) = self.inputs.iter().position(|input| input.topic == *topic) {
                return Err((
                    format!("{entry}.topic"),
                    format!("{topic} is also read by in[{i}]: the bridge would read back what it writes"),
                ));
            }
        }
        Ok(())
    }
}

fn check_topic(topic: &str) -> Result<(), String> {
    let valid = topic.starts_with('/')
        && topic.len() > 1
        && !topic.ends_with('/')
        && topic.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'/');
    if valid { Ok(()) } else { Err(format!("{topic:?} is not an absolute ROS 2 topic name (/a/b_c)")) }
}

fn check_rate(rate_hz: f64) -> Result<(), String> {
    if rate_hz.is_finite() && rate_hz > 0.0 && rate_hz <= 10_000.0 {
        Ok(())
    } else {
        Err(format!("{rate_hz} Hz is not a rate in (0, 10000]"))
    }
}

/// The DDS topic of a ROS 2 topic: `/scan` → `rt/scan`.
pub fn dds_topic(topic: &str) -> String {
    format!("rt{topic}")
}

/// The DDS type name of a ROS 2 type: `sensor_msgs/msg/LaserScan` → `sensor_msgs::msg::dds_::LaserScan_`.
pub fn dds_type(type_name: &str) -> String {
    match type_name.rsplit_once('/') {
        Some((package_and_kind, name)) => format!("{}::dds_::{name}_", package_and_kind.replace('/', "::")),
        None => type_name.to_owned(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const EXAMPLE: &str = r#"
        ros_domain = 7
        [[in]]
        topic = "/scan"
        type = "sensor_msgs/msg/LaserScan"
        max_rate_hz = 5.0
        [[in]]
        topic = "/robot/tf_static"
        type = "tf2_msgs/msg/TFMessage"
        qos = "static"
        [tf_out]
        rate_hz = 10.0
        static_frames = ["laser"]
        [[laser_out]]
        node = "/scan"
        topic = "/graph/scan"
        rate_hz = 10.0
    "#;

    #[test]
    fn a_bridge_file_reads_with_its_defaults() {
        let config = BridgeConfig::parse(EXAMPLE, "example.toml").unwrap();
        assert_eq!((config.ros_domain, config.dsr_domain, config.dsr_prefix.as_str()), (7, 0, "dsr"));
        assert_eq!(config.inputs[0].qos, QosProfile::Sensor);
        assert_eq!(config.inputs[1].qos, QosProfile::Static);
        assert_eq!(config.laser_out[0].range_max_m, 100.0);
        assert_eq!(config.tf_out.unwrap().static_frames, vec!["laser".to_owned()]);
    }

    #[test]
    fn a_bad_field_is_named_with_its_entry() {
        let bad_type = EXAMPLE.replace("sensor_msgs/msg/LaserScan", "sensor_msgs/msg/Foo");
        let error = BridgeConfig::parse(&bad_type, "x.toml").unwrap_err().to_string();
        assert!(error.starts_with("x.toml: in[0].type:"), "{error}");
        let bad_rate = EXAMPLE.replace("max_rate_hz = 5.0", "max_rate_hz = -1.0");
        assert!(BridgeConfig::parse(&bad_rate, "x.toml").unwrap_err().to_string().contains("in[0].max_rate_hz"));
        let bad_topic = EXAMPLE.replace("\"/graph/scan\"", "\"graph scan\"");
        assert!(BridgeConfig::parse(&bad_topic, "x.toml").unwrap_err().to_string().contains("laser_out[0].topic"));
        let echo = EXAMPLE.replace("\"/graph/scan\"", "\"/scan\"");
        let error = BridgeConfig::parse(&echo, "x.toml").unwrap_err().to_string();
        assert!(error.contains("laser_out[0].topic") && error.contains("also read by in[0]"), "{error}");
        let unknown = format!("{EXAMPLE}\nspeed = 3\n");
        assert!(BridgeConfig::parse(&unknown, "x.toml").unwrap_err().to_string().contains("speed"));
    }

    #[test]
    fn ros2_names_map_to_their_dds_names() {
        assert_eq!(dds_topic("/scan"), "rt/scan");
        assert_eq!(dds_type("sensor_msgs/msg/LaserScan"), "sensor_msgs::msg::dds_::LaserScan_");
        assert_eq!(dds_type("tf2_msgs/msg/TFMessage"), "tf2_msgs::msg::dds_::TFMessage_");
    }
}

//! Which topics of an MCAP file are read: the options' or the defaults (see `super`'s docs).

use std::collections::BTreeMap;

use super::{CAMERA_INFO, IMAGE, McapTopics, POSE_STAMPED};

/// A channel of the file.
#[derive(Clone, Debug)]
pub(super) struct ChannelInfo {
    pub(super) topic: String,
    pub(super) schema: String,
}

/// The topics read: the options' or the defaults (module docs).
#[derive(Debug, PartialEq)]
pub(super) struct Chosen {
    pub(super) colour: String,
    pub(super) depth: String,
    pub(super) camera_info: Option<String>,
    pub(super) pose: Option<String>,
}

pub(super) fn choose_topics(channels: &BTreeMap<u16, ChannelInfo>, options: &McapTopics) -> Result<Chosen, String> {
    let of_schema = |schema: &str| -> Vec<&str> {
        let mut topics: Vec<&str> =
            channels.values().filter(|c| c.schema == schema).map(|c| c.topic.as_str()).collect();
        topics.dedup();
        topics
    };
    let images = of_schema(IMAGE);
    let given = |flag: &str, topic: &Option<String>, schema: &str| -> Result<Option<String>, String> {
        let Some(topic) = topic else { return Ok(None) };
        match channels.values().find(|c| &c.topic == topic) {
            Some(c) if c.schema == schema => Ok(Some(topic.clone())),
            Some(c) => Err(format!("{flag} `{topic}` has schema `{}`, not {schema}", c.schema)),
            None => Err(format!("{flag} `{topic}` is not in the file; its {schema} topics: {:?}", of_schema(schema))),
        }
    };
    let one = |what: &str, candidates: Vec<&str>, flag: &str| -> Result<String, String> {
        match candidates[..] {
            [topic] => Ok(topic.to_owned()),
            [] => Err(format!("no {what} topic (sensor_msgs/msg/Image topics: {images:?}); name it with {flag}")),
            _ => Err(format!("several {what} topics {candidates:?}; choose one with {flag}")),
        }
    };
    let depth = match given("--depth-topic", &options.depth, IMAGE)? {
        Some(topic) => topic,
        None => one("depth", images.iter().copied().filter(|t| t.contains("depth")).collect(), "--depth-topic")?,
    };
    let colour = match given("--colour-topic", &options.colour, IMAGE)? {
        Some(topic) => topic,
        None => one("colour", images.iter().copied().filter(|&t| t != depth).collect(), "--colour-topic")?,
    };
    let camera_info = match given("--camera-info-topic", &options.camera_info, CAMERA_INFO)? {
        Some(topic) => Some(topic),
        None => {
            let infos = of_schema(CAMERA_INFO);
            let beside = depth.rsplit_once('/').map(|(namespace, _)| format!("{namespace}/camera_info"));
            match (beside.filter(|b| infos.contains(&b.as_str())), &infos[..]) {
                (Some(topic), _) => Some(topic),
                (None, []) => None,
                (None, [topic]) => Some((*topic).to_owned()),
                (None, _) => {
                    return Err(format!("several camera info topics {infos:?}; choose one with --camera-info-topic"));
                }
            }
        }
    };
    let pose = match given("--pose-topic", &options.pose, POSE_STAMPED)? {
        Some(topic) => Some(topic),
        None => match of_schema(POSE_STAMPED)[..] {
            [] => None,
            [topic] => Some(topic.to_owned()),
            ref several => return Err(format!("several pose topics {several:?}; choose one with --pose-topic")),
        },
    };
    Ok(Chosen { colour, depth, camera_info, pose })
}

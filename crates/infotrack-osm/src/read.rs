//! Reading an OpenStreetMap extract: the nodes inside a box and the ways that may matter
//! (roads, tunnels, woods), from `.osm.pbf` (the `osmpbf` crate) or `.osm` XML (its
//! elements read with `roxmltree`).

use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::Path;

use osmpbf::{Element, ElementReader};

use crate::{Bbox, OsmError};

/// The OSM data an import works on.
#[derive(Debug, Default)]
pub struct OsmData {
    /// The positions of the nodes the ways use, `[longitude, latitude]` in degrees (WGS84).
    pub nodes: HashMap<i64, [f64; 2]>,
    /// The ways with a tag an import reads.
    pub ways: Vec<Way>,
    /// Multipolygon relations with a wood or forest tag (not read: said in the summary).
    pub wood_relations: usize,
}

/// One OSM way.
#[derive(Debug, Clone, PartialEq)]
pub struct Way {
    /// Its OSM id.
    pub id: i64,
    /// Its nodes in order.
    pub refs: Vec<i64>,
    /// Its tags.
    pub tags: BTreeMap<String, String>,
}

impl Way {
    /// The value of tag `k`.
    pub fn tag(&self, k: &str) -> Option<&str> {
        self.tags.get(k).map(String::as_str)
    }
}

/// Whether a way's tags are ones an import reads (roads, woods).
fn wanted<'a>(mut tags: impl Iterator<Item = (&'a str, &'a str)>) -> bool {
    tags.any(|(k, v)| {
        k == "highway" || (k == "landuse" && v == "forest") || (k == "natural" && v == "wood")
    })
}

/// Reads `path`: `.osm.pbf` by its name, anything else as OSM XML.
pub fn read(path: &Path, bbox: &Bbox) -> Result<OsmData, OsmError> {
    let name = path.to_string_lossy();
    if name.ends_with(".pbf") {
        read_pbf(path, bbox)
    } else {
        read_xml(path, bbox)
    }
}

/// Reads an `.osm.pbf` extract in two passes: the ways an import reads, then the nodes
/// they use (inside the box or not: a wood may reach out of it).
pub fn read_pbf(path: &Path, _bbox: &Bbox) -> Result<OsmData, OsmError> {
    let open = || ElementReader::from_path(path).map_err(|e| OsmError::read(path, e));
    let mut data = OsmData::default();
    open()?
        .for_each(|element| match element {
            Element::Way(w) if wanted(w.tags()) => data.ways.push(Way {
                id: w.id(),
                refs: w.refs().collect(),
                tags: w.tags().map(|(k, v)| (k.into(), v.into())).collect(),
            }),
            Element::Relation(r) if wood_relation(r.tags()) => data.wood_relations += 1,
            _ => {}
        })
        .map_err(|e| OsmError::read(path, e))?;
    let used: HashSet<i64> = data
        .ways
        .iter()
        .flat_map(|w| w.refs.iter().copied())
        .collect();
    let mut keep = |id: i64, lon: f64, lat: f64| {
        if used.contains(&id) {
            data.nodes.insert(id, [lon, lat]);
        }
    };
    open()?
        .for_each(|element| match element {
            Element::Node(n) => keep(n.id(), n.lon(), n.lat()),
            Element::DenseNode(n) => keep(n.id(), n.lon(), n.lat()),
            _ => {}
        })
        .map_err(|e| OsmError::read(path, e))?;
    Ok(data)
}

/// A multipolygon of woods (not read; counted).
fn wood_relation<'a>(tags: impl Iterator<Item = (&'a str, &'a str)> + Clone) -> bool {
    wanted(tags.clone()) && !tags.clone().any(|(k, _)| k == "highway")
}

/// The largest OSM XML file read, bytes: a town's extract is a few tens of MB.
const MAX_XML_BYTES: u64 = 512 << 20;

/// Reads an `.osm` XML extract: the ways an import reads and the nodes they use.
pub fn read_xml(path: &Path, _bbox: &Bbox) -> Result<OsmData, OsmError> {
    let text =
        infotrack_files::read_text(path, MAX_XML_BYTES).map_err(|e| OsmError::read(path, e))?;
    let doc = roxmltree::Document::parse(&text).map_err(|e| OsmError::read(path, e))?;
    let malformed = |el: &roxmltree::Node, message: &str| OsmError::Element {
        path: path.to_path_buf(),
        line: doc.text_pos_at(el.range().start).row,
        message: message.into(),
    };
    let elements = || doc.root_element().children().filter(|n| n.is_element());
    let mut data = OsmData::default();
    for el in elements() {
        match el.tag_name().name() {
            "way" => {
                let way = way_of(&el).ok_or_else(|| {
                    malformed(&el, "a way needs a numeric id and numeric nd refs")
                })?;
                if wanted(way.tags.iter().map(|(k, v)| (k.as_str(), v.as_str()))) {
                    data.ways.push(way);
                }
            }
            "relation" if wood_relation(tags_of(&el)) => data.wood_relations += 1,
            _ => {}
        }
    }
    let used: HashSet<i64> = data
        .ways
        .iter()
        .flat_map(|w| w.refs.iter().copied())
        .collect();
    for el in elements().filter(|e| e.has_tag_name("node")) {
        let (id, lon, lat) =
            node_of(&el).ok_or_else(|| malformed(&el, "a node needs a numeric id, lat and lon"))?;
        if used.contains(&id) {
            data.nodes.insert(id, [lon, lat]);
        }
    }
    Ok(data)
}

fn tags_of<'a>(el: &roxmltree::Node<'a, '_>) -> impl Iterator<Item = (&'a str, &'a str)> + Clone {
    el.children()
        .filter(|c| c.has_tag_name("tag"))
        .filter_map(|c| Some((c.attribute("k")?, c.attribute("v")?)))
}

fn node_of(el: &roxmltree::Node) -> Option<(i64, f64, f64)> {
    let num = |k: &str| el.attribute(k)?.parse::<f64>().ok();
    let id = el.attribute("id")?.parse().ok()?;
    Some((id, num("lon")?, num("lat")?))
}

fn way_of(el: &roxmltree::Node) -> Option<Way> {
    let refs = el
        .children()
        .filter(|c| c.has_tag_name("nd"))
        .map(|c| c.attribute("ref")?.parse().ok())
        .collect::<Option<Vec<i64>>>()?;
    Some(Way {
        id: el.attribute("id")?.parse().ok()?,
        refs,
        tags: tags_of(el).map(|(k, v)| (k.into(), v.into())).collect(),
    })
}

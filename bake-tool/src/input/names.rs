//! What a species label names: a Latin genus (the first word, past a hybrid
//! sign), a common name in English, Dutch, German, French or Spanish (whole
//! words, or the end of a Dutch or German compound: `zomereik`, `Stieleiche`),
//! a code through a species table (`--species-table`: ForestGEO `spptable`s,
//! US FIA `REF_SPECIES`, any `code,latin` list), and the family of a genus.
//!
//! Labels are compared lowercased with accents folded (`Chêne` as `chene`,
//! `Lärche` as `larche`, `Fächer` as `facher`).

use std::collections::HashMap;
use std::path::Path;

use anyhow::{bail, Context, Result};

/// `label` lowercased, accents folded to their base letter, `ß` as `ss`.
#[must_use]
pub fn fold(label: &str) -> String {
    let mut out = String::with_capacity(label.len());
    for c in label.trim().chars().flat_map(char::to_lowercase) {
        match c {
            'à' | 'á' | 'â' | 'ã' | 'ä' | 'å' => out.push('a'),
            'ç' => out.push('c'),
            'è' | 'é' | 'ê' | 'ë' => out.push('e'),
            'ì' | 'í' | 'î' | 'ï' => out.push('i'),
            'ñ' => out.push('n'),
            'ò' | 'ó' | 'ô' | 'õ' | 'ö' | 'ø' => out.push('o'),
            'ù' | 'ú' | 'û' | 'ü' => out.push('u'),
            'ý' | 'ÿ' => out.push('y'),
            'ß' => out.push_str("ss"),
            'œ' => out.push_str("oe"),
            'æ' => out.push_str("ae"),
            c => out.push(c),
        }
    }
    out
}

/// The words of a folded label (letters only).
fn words(folded: &str) -> Vec<&str> {
    folded.split(|c: char| !c.is_alphabetic()).filter(|w| !w.is_empty()).collect()
}

/// The label's Latin genus candidate: its first word, past a hybrid sign
/// (`x Cupressocyparis`, `× Chitalpa`), folded.
#[must_use]
pub fn first_word(label: &str) -> String {
    let f = fold(label);
    let mut w = words(&f).into_iter();
    let first = w.next().unwrap_or("");
    if first == "x" { w.next().unwrap_or("") } else { first }.to_string()
}

/// Common names → genus (the library's, or one whose family it knows), whole
/// words (several words: all, in order). The longest name a label holds wins
/// (`horse chestnut` over `chestnut`).
const COMMON_NAMES: &[(&str, &str)] = &[
    // Quercus
    ("oak", "quercus"),
    ("pin oak", "quercus"),
    ("eik", "quercus"),
    ("eiche", "quercus"),
    ("chene", "quercus"),
    ("roble", "quercus"),
    ("encina", "quercus"),
    ("alcornoque", "quercus"),
    ("quejigo", "quercus"),
    ("rebollo", "quercus"),
    // Fagus
    ("beech", "fagus"),
    ("beuk", "fagus"),
    ("buche", "fagus"),
    ("hetre", "fagus"),
    ("haya", "fagus"),
    // Castanea
    ("chestnut", "castanea"),
    ("sweet chestnut", "castanea"),
    ("tamme kastanje", "castanea"),
    ("kastanje", "castanea"),
    ("edelkastanie", "castanea"),
    ("kastanie", "castanea"),
    ("chataignier", "castanea"),
    ("castano", "castanea"),
    // Acer
    ("maple", "acer"),
    ("sycamore maple", "acer"),
    ("box elder", "acer"),
    ("esdoorn", "acer"),
    ("ahorn", "acer"),
    ("erable", "acer"),
    ("arce", "acer"),
    // Aesculus
    ("horse chestnut", "aesculus"),
    ("horsechestnut", "aesculus"),
    ("buckeye", "aesculus"),
    ("paardenkastanje", "aesculus"),
    ("rosskastanie", "aesculus"),
    ("marronnier", "aesculus"),
    ("castano de indias", "aesculus"),
    // Tilia
    ("linden", "tilia"),
    ("lime", "tilia"),
    ("basswood", "tilia"),
    ("linde", "tilia"),
    ("tilleul", "tilia"),
    ("tilo", "tilia"),
    // Platanus
    ("plane", "platanus"),
    ("sycamore", "platanus"),
    ("plataan", "platanus"),
    ("platane", "platanus"),
    ("platano", "platanus"),
    ("platano de sombra", "platanus"),
    // Betula
    ("birch", "betula"),
    ("berk", "betula"),
    ("birke", "betula"),
    ("bouleau", "betula"),
    ("abedul", "betula"),
    // Alnus
    ("alder", "alnus"),
    ("els", "alnus"),
    ("erle", "alnus"),
    ("aulne", "alnus"),
    ("verne", "alnus"),
    ("aliso", "alnus"),
    // Carpinus
    ("hornbeam", "carpinus"),
    ("haagbeuk", "carpinus"),
    ("hainbuche", "carpinus"),
    ("charme", "carpinus"),
    ("carpe", "carpinus"),
    // Corylus
    ("hazel", "corylus"),
    ("filbert", "corylus"),
    ("hazelaar", "corylus"),
    ("hasel", "corylus"),
    ("noisetier", "corylus"),
    ("avellano", "corylus"),
    // Populus
    ("poplar", "populus"),
    ("aspen", "populus"),
    ("cottonwood", "populus"),
    ("populier", "populus"),
    ("ratelpopulier", "populus"),
    ("pappel", "populus"),
    ("espe", "populus"),
    ("peuplier", "populus"),
    ("tremble", "populus"),
    ("alamo", "populus"),
    ("chopo", "populus"),
    // Salix
    ("willow", "salix"),
    ("wilg", "salix"),
    ("weide", "salix"),
    ("saule", "salix"),
    ("sauce", "salix"),
    // Fraxinus
    ("ash", "fraxinus"),
    ("es", "fraxinus"),
    ("esche", "fraxinus"),
    ("frene", "fraxinus"),
    ("fresno", "fraxinus"),
    // Olea
    ("olive", "olea"),
    ("olijf", "olea"),
    ("olivenbaum", "olea"),
    ("olivier", "olea"),
    ("olivo", "olea"),
    // Ulmus
    ("elm", "ulmus"),
    ("iep", "ulmus"),
    ("olm", "ulmus"),
    ("ulme", "ulmus"),
    ("orme", "ulmus"),
    ("olmo", "ulmus"),
    // Zelkova, Celtis
    ("zelkova", "zelkova"),
    ("japanese elm", "zelkova"),
    ("hackberry", "celtis"),
    ("nettle tree", "celtis"),
    ("netelboom", "celtis"),
    ("zurgel", "celtis"),
    ("micocoulier", "celtis"),
    ("almez", "celtis"),
    // Fabaceae
    ("black locust", "robinia"),
    ("locust", "robinia"),
    ("acacia", "robinia"),
    ("false acacia", "robinia"),
    ("robinier", "robinia"),
    ("falsa acacia", "robinia"),
    ("honey locust", "gleditsia"),
    ("honeylocust", "gleditsia"),
    ("valse christusdoorn", "gleditsia"),
    ("christusdoorn", "gleditsia"),
    ("gleditschie", "gleditsia"),
    ("lederhulsenbaum", "gleditsia"),
    ("fevier", "gleditsia"),
    ("acacia de tres espinas", "gleditsia"),
    // Rosaceae
    ("cherry", "prunus"),
    ("pin cherry", "prunus"),
    ("plum", "prunus"),
    ("blackthorn", "prunus"),
    ("kers", "prunus"),
    ("pruim", "prunus"),
    ("kirsche", "prunus"),
    ("pflaume", "prunus"),
    ("cerisier", "prunus"),
    ("merisier", "prunus"),
    ("prunier", "prunus"),
    ("cerezo", "prunus"),
    ("ciruelo", "prunus"),
    ("apple", "malus"),
    ("crabapple", "malus"),
    ("crab apple", "malus"),
    ("appel", "malus"),
    ("apfel", "malus"),
    ("pommier", "malus"),
    ("manzano", "malus"),
    ("pear", "pyrus"),
    ("peer", "pyrus"),
    ("birne", "pyrus"),
    ("poirier", "pyrus"),
    ("peral", "pyrus"),
    ("rowan", "sorbus"),
    ("whitebeam", "sorbus"),
    ("mountain ash", "sorbus"),
    ("service tree", "sorbus"),
    ("lijsterbes", "sorbus"),
    ("meelbes", "sorbus"),
    ("eberesche", "sorbus"),
    ("vogelbeere", "sorbus"),
    ("mehlbeere", "sorbus"),
    ("elsbeere", "sorbus"),
    ("sorbier", "sorbus"),
    ("alisier", "sorbus"),
    ("serbal", "sorbus"),
    ("hawthorn", "crataegus"),
    ("meidoorn", "crataegus"),
    ("weissdorn", "crataegus"),
    ("aubepine", "crataegus"),
    ("espino albar", "crataegus"),
    ("majuelo", "crataegus"),
    // Others
    ("walnut", "juglans"),
    ("walnoot", "juglans"),
    ("walnuss", "juglans"),
    ("nussbaum", "juglans"),
    ("noyer", "juglans"),
    ("nogal", "juglans"),
    ("sweetgum", "liquidambar"),
    ("sweet gum", "liquidambar"),
    ("amberboom", "liquidambar"),
    ("amberbaum", "liquidambar"),
    ("copalme", "liquidambar"),
    ("tulip tree", "liriodendron"),
    ("tuliptree", "liriodendron"),
    ("tulip poplar", "liriodendron"),
    ("tulpenboom", "liriodendron"),
    ("tulpenbaum", "liriodendron"),
    ("tulipier", "liriodendron"),
    ("tulipero", "liriodendron"),
    ("beverboom", "magnolia"),
    ("magnolie", "magnolia"),
    ("magnolier", "magnolia"),
    ("trompetboom", "catalpa"),
    ("trompetenbaum", "catalpa"),
    ("gum tree", "eucalyptus"),
    ("eukalyptus", "eucalyptus"),
    ("eucalipto", "eucalyptus"),
    ("maidenhair tree", "ginkgo"),
    ("japanse notenboom", "ginkgo"),
    ("facherblattbaum", "ginkgo"),
    ("arbre aux quarante ecus", "ginkgo"),
    ("kornelkirsche", "cornus"),
    ("cornelian cherry", "cornus"),
    ("dogwood", "cornus"),
    ("kornoelje", "cornus"),
    ("tree of heaven", "ailanthus"),
    ("hemelboom", "ailanthus"),
    ("gotterbaum", "ailanthus"),
    ("ailante", "ailanthus"),
    ("ailanto", "ailanthus"),
    ("mulberry", "morus"),
    ("moerbei", "morus"),
    ("maulbeere", "morus"),
    ("maulbeerbaum", "morus"),
    ("murier", "morus"),
    ("morera", "morus"),
    // Palms
    ("date palm", "phoenix"),
    ("dadelpalm", "phoenix"),
    ("dattelpalme", "phoenix"),
    ("palmier dattier", "phoenix"),
    ("palmera datilera", "phoenix"),
    ("palmera canaria", "phoenix"),
    ("palm", "phoenix"),
    ("palmier", "phoenix"),
    ("palmera", "phoenix"),
    ("palme", "phoenix"),
    ("mexican fan palm", "washingtonia"),
    ("california fan palm", "washingtonia"),
    ("fan palm", "washingtonia"),
    ("windmill palm", "trachycarpus"),
    ("chusan palm", "trachycarpus"),
    ("hennepalm", "trachycarpus"),
    ("hanfpalme", "trachycarpus"),
    ("palmier de chine", "trachycarpus"),
    ("palmito elevado", "trachycarpus"),
    // Pinaceae
    ("pine", "pinus"),
    ("den", "pinus"),
    ("grove den", "pinus"),
    ("kiefer", "pinus"),
    ("fohre", "pinus"),
    ("pin", "pinus"),
    ("pino", "pinus"),
    ("spruce", "picea"),
    ("spar", "picea"),
    ("fijnspar", "picea"),
    ("fichte", "picea"),
    ("epicea", "picea"),
    ("abeto rojo", "picea"),
    ("fir", "abies"),
    ("zilverspar", "abies"),
    ("edelspar", "abies"),
    ("tanne", "abies"),
    ("sapin", "abies"),
    ("abeto", "abies"),
    ("larch", "larix"),
    ("tamarack", "larix"),
    ("lariks", "larix"),
    ("larche", "larix"),
    ("meleze", "larix"),
    ("alerce", "larix"),
    ("douglas", "pseudotsuga"),
    ("douglas fir", "pseudotsuga"),
    ("douglasspar", "pseudotsuga"),
    ("douglasie", "pseudotsuga"),
    ("douglastanne", "pseudotsuga"),
    ("schierlingstanne", "tsuga"),
    ("sapin de douglas", "pseudotsuga"),
    ("abeto de douglas", "pseudotsuga"),
    ("hemlock", "tsuga"),
    ("hemlockspar", "tsuga"),
    ("hemlocktanne", "tsuga"),
    ("pruche", "tsuga"),
    ("cedar", "cedrus"),
    ("ceder", "cedrus"),
    ("zeder", "cedrus"),
    ("cedre", "cedrus"),
    ("cedro", "cedrus"),
    // Cupressaceae, Taxaceae
    ("arborvitae", "thuja"),
    ("levensboom", "thuja"),
    ("lebensbaum", "thuja"),
    ("thuya", "thuja"),
    ("tuya", "thuja"),
    ("western red cedar", "thuja"),
    ("red cedar", "thuja"),
    ("white cedar", "thuja"),
    ("eastern red cedar", "juniperus"),
    ("incense cedar", "calocedrus"),
    ("false cypress", "chamaecyparis"),
    ("lawson cypress", "chamaecyparis"),
    ("schijncipres", "chamaecyparis"),
    ("scheinzypresse", "chamaecyparis"),
    ("faux cypres", "chamaecyparis"),
    ("cipres de lawson", "chamaecyparis"),
    ("cypress", "cupressus"),
    ("cipres", "cupressus"),
    ("zypresse", "cupressus"),
    ("cypres", "cupressus"),
    ("juniper", "juniperus"),
    ("jeneverbes", "juniperus"),
    ("wacholder", "juniperus"),
    ("genevrier", "juniperus"),
    ("enebro", "juniperus"),
    ("sabina", "juniperus"),
    ("redwood", "sequoia"),
    ("coast redwood", "sequoia"),
    ("kustmammoetboom", "sequoia"),
    ("kustenmammutbaum", "sequoia"),
    ("sequoia geant", "sequoiadendron"),
    ("giant sequoia", "sequoiadendron"),
    ("giant redwood", "sequoiadendron"),
    ("wellingtonia", "sequoiadendron"),
    ("mammoetboom", "sequoiadendron"),
    ("mammutbaum", "sequoiadendron"),
    ("riesenmammutbaum", "sequoiadendron"),
    ("dawn redwood", "metasequoia"),
    ("watercipres", "metasequoia"),
    ("urweltmammutbaum", "metasequoia"),
    ("bald cypress", "taxodium"),
    ("swamp cypress", "taxodium"),
    ("moerascipres", "taxodium"),
    ("sumpfzypresse", "taxodium"),
    ("cypres chauve", "taxodium"),
    ("cipres calvo", "taxodium"),
    ("yew", "taxus"),
    ("eibe", "taxus"),
    ("if", "taxus"),
    ("tejo", "taxus"),
];

/// Ends of Dutch and German compounds → genus (`zomereik`, `Stieleiche`,
/// `Winterlinde`, `Bergahorn`, `sierkers`): a word that ends with one, when no
/// whole word names a genus. The longest end wins.
const COMPOUND_ENDS: &[(&str, &str)] = &[
    ("eik", "quercus"),
    ("eiche", "quercus"),
    ("beuk", "fagus"),
    ("buche", "fagus"),
    ("esdoorn", "acer"),
    ("ahorn", "acer"),
    ("linde", "tilia"),
    ("plataan", "platanus"),
    ("platane", "platanus"),
    ("berk", "betula"),
    ("birke", "betula"),
    ("erle", "alnus"),
    ("hasel", "corylus"),
    ("populier", "populus"),
    ("pappel", "populus"),
    ("wilg", "salix"),
    ("weide", "salix"),
    ("esche", "fraxinus"),
    ("ulme", "ulmus"),
    ("iep", "ulmus"),
    ("kers", "prunus"),
    ("kirsche", "prunus"),
    ("pruim", "prunus"),
    ("pflaume", "prunus"),
    ("appel", "malus"),
    ("apfel", "malus"),
    ("peer", "pyrus"),
    ("birne", "pyrus"),
    ("meidoorn", "crataegus"),
    ("kastanje", "castanea"),
    ("kastanie", "castanea"),
    ("walnoot", "juglans"),
    ("kiefer", "pinus"),
    ("fichte", "picea"),
    ("spar", "picea"),
    ("tanne", "abies"),
    ("larche", "larix"),
    ("lariks", "larix"),
    ("zeder", "cedrus"),
    ("ceder", "cedrus"),
    ("zypresse", "cupressus"),
    ("cipres", "cupressus"),
    ("wacholder", "juniperus"),
    ("eibe", "taxus"),
    ("palme", "phoenix"),
    ("palm", "phoenix"),
];

/// The genus a common name in `label` names (lowercase Latin), if any.
#[must_use]
pub fn common_genus(label: &str) -> Option<&'static str> {
    let f = fold(label);
    let w = words(&f);
    let whole = COMMON_NAMES
        .iter()
        .filter(|(name, _)| {
            let parts: Vec<&str> = name.split(' ').collect();
            w.windows(parts.len()).any(|x| x == parts.as_slice())
        })
        .max_by_key(|(name, _)| name.len());
    if let Some((_, g)) = whole {
        return Some(g);
    }
    COMPOUND_ENDS
        .iter()
        .filter(|(end, _)| w.iter().any(|x| x.len() > end.len() + 1 && x.ends_with(end)))
        .max_by_key(|(end, _)| end.len())
        .map(|(_, g)| *g)
}

/// Families of tree genera the library has no tree of (the library's own
/// genera carry theirs): an unknown genus of a family the library knows
/// takes that family's tree.
const FAMILIES: &[(&str, &str)] = &[
    ("ostrya", "Betulaceae"),
    ("nothofagus", "Nothofagaceae"),
    ("lithocarpus", "Fagaceae"),
    ("castanopsis", "Fagaceae"),
    ("chrysolepis", "Fagaceae"),
    ("notholithocarpus", "Fagaceae"),
    ("carya", "Juglandaceae"),
    ("pterocarya", "Juglandaceae"),
    ("koelreuteria", "Sapindaceae"),
    ("sapindus", "Sapindaceae"),
    ("amelanchier", "Rosaceae"),
    ("cotoneaster", "Rosaceae"),
    ("photinia", "Rosaceae"),
    ("cydonia", "Rosaceae"),
    ("mespilus", "Rosaceae"),
    ("heteromeles", "Rosaceae"),
    ("cercocarpus", "Rosaceae"),
    ("cercis", "Fabaceae"),
    ("albizia", "Fabaceae"),
    ("acacia", "Fabaceae"),
    ("laburnum", "Fabaceae"),
    ("cladrastis", "Fabaceae"),
    ("styphnolobium", "Fabaceae"),
    ("sophora", "Fabaceae"),
    ("gymnocladus", "Fabaceae"),
    ("maackia", "Fabaceae"),
    ("prosopis", "Fabaceae"),
    ("ceratonia", "Fabaceae"),
    ("parrotia", "Hamamelidaceae"),
    ("hamamelis", "Hamamelidaceae"),
    ("nyssa", "Nyssaceae"),
    ("davidia", "Nyssaceae"),
    ("cornus", "Cornaceae"),
    ("ilex", "Aquifoliaceae"),
    ("syringa", "Oleaceae"),
    ("ligustrum", "Oleaceae"),
    ("phillyrea", "Oleaceae"),
    ("osmanthus", "Oleaceae"),
    ("ficus", "Moraceae"),
    ("maclura", "Moraceae"),
    ("broussonetia", "Moraceae"),
    ("hemiptelea", "Ulmaceae"),
    ("planera", "Ulmaceae"),
    ("elaeagnus", "Elaeagnaceae"),
    ("hippophae", "Elaeagnaceae"),
    ("melia", "Meliaceae"),
    ("toona", "Meliaceae"),
    ("cedrela", "Meliaceae"),
    ("paulownia", "Paulowniaceae"),
    ("jacaranda", "Bignoniaceae"),
    ("chitalpa", "Bignoniaceae"),
    ("tabebuia", "Bignoniaceae"),
    ("arbutus", "Ericaceae"),
    ("rhododendron", "Ericaceae"),
    ("arctostaphylos", "Ericaceae"),
    ("laurus", "Lauraceae"),
    ("cinnamomum", "Lauraceae"),
    ("umbellularia", "Lauraceae"),
    ("sassafras", "Lauraceae"),
    ("persea", "Lauraceae"),
    ("corymbia", "Myrtaceae"),
    ("melaleuca", "Myrtaceae"),
    ("callistemon", "Myrtaceae"),
    ("metrosideros", "Myrtaceae"),
    ("ceanothus", "Rhamnaceae"),
    ("frangula", "Rhamnaceae"),
    ("rhamnus", "Rhamnaceae"),
    ("euonymus", "Celastraceae"),
    ("viburnum", "Viburnaceae"),
    ("sambucus", "Viburnaceae"),
    ("phellodendron", "Rutaceae"),
    ("tetradium", "Rutaceae"),
    ("citrus", "Rutaceae"),
    ("firmiana", "Malvaceae"),
    ("schinus", "Anacardiaceae"),
    ("rhus", "Anacardiaceae"),
    ("cotinus", "Anacardiaceae"),
    ("pistacia", "Anacardiaceae"),
    ("kalopanax", "Araliaceae"),
    ("michelia", "Magnoliaceae"),
    ("halesia", "Styracaceae"),
    ("styrax", "Styracaceae"),
    ("diospyros", "Ebenaceae"),
    ("cercidiphyllum", "Cercidiphyllaceae"),
    ("tamarix", "Tamaricaceae"),
    ("buxus", "Buxaceae"),
    ("cryptomeria", "Cupressaceae"),
    ("xanthocyparis", "Cupressaceae"),
    ("cupressocyparis", "Cupressaceae"),
    ("platycladus", "Cupressaceae"),
    ("cunninghamia", "Cupressaceae"),
    ("thujopsis", "Cupressaceae"),
    ("tetraclinis", "Cupressaceae"),
    ("keteleeria", "Pinaceae"),
    ("pseudolarix", "Pinaceae"),
    ("araucaria", "Araucariaceae"),
    ("agathis", "Araucariaceae"),
    ("wollemia", "Araucariaceae"),
    ("podocarpus", "Podocarpaceae"),
    ("torreya", "Taxaceae"),
    ("cephalotaxus", "Taxaceae"),
    ("sciadopitys", "Sciadopityaceae"),
    ("chamaerops", "Arecaceae"),
    ("livistona", "Arecaceae"),
    ("butia", "Arecaceae"),
    ("sabal", "Arecaceae"),
    ("syagrus", "Arecaceae"),
    ("cocos", "Arecaceae"),
    ("roystonea", "Arecaceae"),
    ("archontophoenix", "Arecaceae"),
    ("howea", "Arecaceae"),
    ("jubaea", "Arecaceae"),
    ("brahea", "Arecaceae"),
];

/// Families with no tree of their own in the library, and the archetype
/// drawn for them (their typical habit).
pub const FAMILY_ARCHETYPES: &[(&str, &str)] = &[
    ("Nothofagaceae", "broadleaf-oval"),
    ("Hamamelidaceae", "multi-stem"),
    ("Nyssaceae", "broadleaf-oval"),
    ("Cornaceae", "multi-stem"),
    ("Aquifoliaceae", "broadleaf-oval"),
    ("Elaeagnaceae", "shrub"),
    ("Meliaceae", "broadleaf-round"),
    ("Paulowniaceae", "broadleaf-spreading"),
    ("Ericaceae", "shrub"),
    ("Lauraceae", "broadleaf-round"),
    ("Rhamnaceae", "shrub"),
    ("Celastraceae", "shrub"),
    ("Viburnaceae", "shrub"),
    ("Rutaceae", "broadleaf-round"),
    ("Anacardiaceae", "multi-stem"),
    ("Araliaceae", "broadleaf-round"),
    ("Styracaceae", "broadleaf-round"),
    ("Ebenaceae", "broadleaf-oval"),
    ("Cercidiphyllaceae", "broadleaf-oval"),
    ("Tamaricaceae", "shrub"),
    ("Buxaceae", "shrub"),
    ("Araucariaceae", "conifer-spire"),
    ("Podocarpaceae", "conifer-spire"),
    ("Sciadopityaceae", "conifer-spire"),
];

/// The family of a genus the library has no tree of (lowercase Latin), if known.
#[must_use]
pub fn family_of(genus: &str) -> Option<&'static str> {
    FAMILIES.iter().find(|(g, _)| *g == genus).map(|(_, f)| *f)
}

/// A species table: codes → Latin names (and families where it gives them).
#[derive(Debug, Clone, Default)]
pub struct SpeciesTable {
    /// Folded code → (Latin name, family).
    codes: HashMap<String, (String, Option<String>)>,
    /// Where it was read from.
    pub source: String,
}

/// Code columns a species table may have.
const CODE_COLUMNS: &[&str] = &["sp", "spcode", "sp_code", "species_code", "speciescode", "code", "spcd", "mnemonic"];
/// Latin-name columns.
const LATIN_COLUMNS: &[&str] =
    &["latin", "latin_name", "latinname", "scientific_name", "scientificname", "sciname", "species_name", "taxon"];

impl SpeciesTable {
    /// Reads a species table (CSV, any delimiter): a code column (`sp`,
    /// `spcode`, `code`, `SPCD`, …) and a Latin name (`Latin`,
    /// `SCIENTIFIC_NAME`, …, or `Genus` and `Species` columns), optionally
    /// `Family`.
    ///
    /// # Errors
    /// An unreadable file, or no code or name columns (the error lists what it looked for).
    pub fn read(path: &Path) -> Result<Self> {
        /// Largest table read (FIA's REF_SPECIES is under 1 MB).
        const MAX_BYTES: u64 = 64 << 20;
        let len =
            std::fs::metadata(path).with_context(|| format!("cannot read --species-table {}", path.display()))?.len();
        if len > MAX_BYTES {
            bail!("--species-table {}: {len} bytes, more than a species table's {MAX_BYTES}", path.display());
        }
        let bytes = std::fs::read(path).with_context(|| format!("cannot read --species-table {}", path.display()))?;
        Self::parse(&bytes, &path.display().to_string())
    }

    /// Reads a species table from its bytes (as [`Self::read`] does a file's);
    /// `source` names it in errors.
    ///
    /// # Errors
    /// No code column, no Latin name column, a row the CSV reader refuses, or no
    /// row with both a code and a name.
    pub fn parse(bytes: &[u8], source: &str) -> Result<Self> {
        let text = String::from_utf8_lossy(bytes);
        let first = text.lines().next().unwrap_or("");
        let delimiter = crate::input::text::detect_delimiter(first.as_bytes());
        let mut rdr = csv::ReaderBuilder::new()
            .delimiter(delimiter)
            .trim(csv::Trim::All)
            .flexible(true)
            .from_reader(text.as_bytes());
        let header: Vec<String> = rdr
            .headers()
            .with_context(|| format!("--species-table {source}"))?
            .iter()
            .map(|h| fold(h).replace(' ', "_"))
            .collect();
        let find = |names: &[&str]| header.iter().position(|h| names.contains(&h.as_str()));
        let code = find(CODE_COLUMNS);
        let latin = find(LATIN_COLUMNS);
        let (genus, species, family) = (find(&["genus"]), find(&["species"]), find(&["family"]));
        let Some(code) = code else {
            bail!(
                "--species-table {source}: no code column (looked for {}; it has {})",
                CODE_COLUMNS.join(", "),
                header.join(", ")
            );
        };
        if latin.is_none() && genus.is_none() {
            bail!(
                "--species-table {source}: no Latin name column (looked for {}, or genus and species; it has {})",
                LATIN_COLUMNS.join(", "),
                header.join(", ")
            );
        }
        let mut codes = HashMap::new();
        for (i, rec) in rdr.records().enumerate() {
            let rec = rec.with_context(|| format!("--species-table {source}: row {}", i + 2))?;
            let cell = |c: Option<usize>| c.and_then(|c| rec.get(c)).unwrap_or("").trim().to_string();
            let key = fold(&cell(Some(code)));
            let name = match latin.map(|c| cell(Some(c))).filter(|n| !n.is_empty()) {
                Some(n) => n,
                None => format!("{} {}", cell(genus), cell(species)).trim().to_string(),
            };
            if key.is_empty() || name.is_empty() {
                continue;
            }
            let fam = Some(cell(family)).filter(|f| !f.is_empty());
            codes.entry(key).or_insert((name, fam));
        }
        if codes.is_empty() {
            bail!("--species-table {source}: no rows with both a code and a name");
        }
        Ok(Self { codes, source: source.to_string() })
    }

    /// The Latin name (and family) a code stands for.
    #[must_use]
    pub fn latin(&self, label: &str) -> Option<(&str, Option<&str>)> {
        self.codes.get(&fold(label)).map(|(n, f)| (n.as_str(), f.as_deref()))
    }

    /// Codes it holds.
    #[must_use]
    pub fn len(&self) -> usize {
        self.codes.len()
    }

    /// Whether it holds none.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.codes.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn common_names_in_five_languages() {
        for (label, want) in [
            ("Red Oak", "quercus"),
            ("Zomereik", "quercus"),
            ("Stieleiche", "quercus"),
            ("Chêne pédonculé", "quercus"),
            ("Roble albar", "quercus"),
            ("Rotbuche", "fagus"),
            ("Hêtre", "fagus"),
            ("Noorse esdoorn", "acer"),
            ("Érable sycomore", "acer"),
            ("Sycamore maple", "acer"),
            ("Gewone paardenkastanje", "aesculus"),
            ("Castaño de Indias", "aesculus"),
            ("Sweet chestnut", "castanea"),
            ("Winterlinde", "tilia"),
            ("Tilleul à petites feuilles", "tilia"),
            ("Gemeine Esche", "fraxinus"),
            ("Fresno común", "fraxinus"),
            ("Fijnspar", "picea"),
            ("Zilverspar", "abies"),
            ("Douglasspar", "pseudotsuga"),
            ("Sapin de Douglas", "pseudotsuga"),
            ("Europäische Lärche", "larix"),
            ("Mélèze d'Europe", "larix"),
            ("Grove den", "pinus"),
            ("Pino silvestre", "pinus"),
            ("Sierkers", "prunus"),
            ("Eastern red cedar", "juniperus"),
            ("Western red cedar", "thuja"),
            ("Cedar of Lebanon", "cedrus"),
            ("Urweltmammutbaum", "metasequoia"),
            ("Palmera datilera", "phoenix"),
        ] {
            assert_eq!(common_genus(label), Some(want), "{label}");
        }
        assert_eq!(common_genus("Quercus robur"), None);
        assert_eq!(common_genus("Species"), None, "no compound end inside an unrelated word");
    }

    #[test]
    fn latin_first_words_skip_hybrid_signs() {
        assert_eq!(first_word("x Cupressocyparis leylandii"), "cupressocyparis");
        assert_eq!(first_word("× Chitalpa tashkentensis"), "chitalpa");
        assert_eq!(first_word("Platanus x hispanica"), "platanus");
        assert_eq!(first_word("  PÍCEA abies"), "picea");
    }

    #[test]
    fn species_tables_are_read_with_their_columns_found() {
        let dir = std::env::temp_dir().join(format!("sylva-names-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // A ForestGEO spptable (genus and species columns), a FIA REF_SPECIES
        // extract (semicolons), a code,latin list.
        let forestgeo = dir.join("spptable.csv");
        std::fs::write(&forestgeo, "sp,Genus,Species,Family,IDLevel\nquerub,Quercus,rubra,Fagaceae,species\nacerru,Acer,rubrum,Sapindaceae,species\n").unwrap();
        let t = SpeciesTable::read(&forestgeo).unwrap();
        assert_eq!(t.latin("QUERUB"), Some(("Quercus rubra", Some("Fagaceae"))));
        assert_eq!(t.len(), 2);
        let fia = dir.join("ref_species.csv");
        std::fs::write(
            &fia,
            "SPCD;COMMON_NAME;GENUS;SPECIES;SCIENTIFIC_NAME\n802;white oak;Quercus;alba;Quercus alba\n",
        )
        .unwrap();
        assert_eq!(SpeciesTable::read(&fia).unwrap().latin("802"), Some(("Quercus alba", None)));
        let bad = dir.join("bad.csv");
        std::fs::write(&bad, "name,colour\nx,y\n").unwrap();
        let e = SpeciesTable::read(&bad).unwrap_err().to_string();
        assert!(e.contains("no code column") && e.contains("bad.csv"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}

// STUB until the xml branch lands.
use crate::error::{Error, Result};
use crate::scene::Node;
use std::path::Path;
use std::rc::Rc;
pub fn parse_file(_p: &Path, _d: &[(String, String)]) -> Result<Rc<Node>> {
    Err(Error::Invalid("stub".into()))
}

//! The stages of `iuq pipeline` that are not verbs of their own: the cell model as a campaign,
//! the pipeline's settings, and the assembly of the report.

pub mod cell_model_campaign;
pub mod report_data;
pub mod settings;

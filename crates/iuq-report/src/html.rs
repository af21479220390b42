//! The self-contained HTML page: inline CSS, inline SVG figures, no scripts and no external
//! resources; only relative links to the report's own SVG, PNG, CSV and JSON files.

use std::fmt::Write;

use crate::format::format_number;
use crate::input::StudyReport;
use crate::sections::Section;
use crate::tables::{Cell, Table};

/// The page's style sheet.
const STYLE: &str = r#"
:root { --ink: #1d1d1f; --muted: #5f6368; --rule: #d9dce1; --band: #f5f6f8; --accent: #1f77b4; }
* { box-sizing: border-box; }
body { margin: 0; color: var(--ink); background: #fff;
  font: 16px/1.55 system-ui, -apple-system, "Segoe UI", "DejaVu Sans", "Helvetica Neue", Arial, sans-serif; }
main { max-width: 1180px; margin: 0 auto; padding: 28px 32px 64px; }
header { border-bottom: 2px solid var(--ink); padding-bottom: 14px; margin-bottom: 18px; }
h1 { font-size: 30px; line-height: 1.2; margin: 0 0 4px; }
.study { color: var(--muted); margin: 0 0 12px; }
dl.provenance { display: grid; grid-template-columns: max-content 1fr; gap: 2px 16px; margin: 0;
  font-size: 14px; }
dl.provenance dt { color: var(--muted); }
dl.provenance dd { margin: 0; font-family: ui-monospace, "DejaVu Sans Mono", Menlo, Consolas, monospace;
  overflow-wrap: anywhere; }
nav ol { columns: 2; margin: 8px 0 0; padding-left: 22px; font-size: 15px; }
a { color: var(--accent); }
section { margin-top: 40px; }
h2 { font-size: 23px; border-bottom: 1px solid var(--rule); padding-bottom: 4px; margin: 0 0 10px; }
h3 { font-size: 17px; margin: 22px 0 6px; }
p.lead { margin: 0 0 14px; max-width: 78ch; }
figure { margin: 16px 0 26px; }
figure .svg svg { display: block; max-width: 100%; height: auto; border: 1px solid var(--rule); }
figcaption { font-size: 14.5px; color: var(--muted); margin-top: 8px; max-width: 100ch; }
figcaption strong { color: var(--ink); }
.links { font-size: 13.5px; color: var(--muted); white-space: nowrap; }
.table-wrap { overflow-x: auto; }
table { border-collapse: collapse; font-size: 14px; margin: 4px 0 4px; }
th, td { padding: 4px 10px; border-bottom: 1px solid var(--rule); text-align: left; vertical-align: baseline; }
thead th { border-bottom: 2px solid var(--ink); font-weight: 600; }
thead tr.groups th { border-bottom: 1px solid var(--ink); text-align: center; }
td.num { text-align: right; font-variant-numeric: tabular-nums;
  font-family: ui-monospace, "DejaVu Sans Mono", Menlo, Consolas, monospace; font-size: 13.5px; }
th.num { text-align: right; }
tbody tr:nth-child(even) { background: var(--band); }
footer { margin-top: 48px; border-top: 1px solid var(--rule); padding-top: 10px; font-size: 13px; color: var(--muted); }
"#;

/// Escapes text for HTML element content and attribute values.
pub(crate) fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            _ => out.push(c),
        }
    }
    out
}

/// A table as HTML: a group header row when columns are grouped, numeric cells right-aligned,
/// formatted by [`format_number`], with the exact value and its `report.json` pointer in
/// `data-value` and `data-pointer`.
pub(crate) fn render_table(table: &Table) -> String {
    let mut html = String::new();
    let grouped = table.columns.iter().any(|c| c.group.is_some());
    let numeric: Vec<bool> = (0..table.columns.len())
        .map(|c| {
            table
                .rows
                .iter()
                .any(|row| matches!(row.get(c), Some(Cell::Number { .. })))
        })
        .collect();
    let header_class = |c: usize| if numeric[c] { " class=\"num\"" } else { "" };
    html.push_str("<div class=\"table-wrap\"><table>\n<thead>\n");
    if grouped {
        html.push_str("<tr class=\"groups\">");
        let mut c = 0;
        while c < table.columns.len() {
            match &table.columns[c].group {
                None => {
                    let _ = write!(
                        html,
                        "<th rowspan=\"2\"{}>{}</th>",
                        header_class(c),
                        escape(&table.columns[c].header)
                    );
                    c += 1;
                }
                Some(group) => {
                    let span = table.columns[c..]
                        .iter()
                        .take_while(|col| col.group.as_ref() == Some(group))
                        .count();
                    let _ = write!(html, "<th colspan=\"{span}\">{}</th>", escape(group));
                    c += span;
                }
            }
        }
        html.push_str("</tr>\n<tr>");
        for (c, column) in table.columns.iter().enumerate() {
            if column.group.is_some() {
                let _ = write!(
                    html,
                    "<th{}>{}</th>",
                    header_class(c),
                    escape(&column.header)
                );
            }
        }
        html.push_str("</tr>\n");
    } else {
        html.push_str("<tr>");
        for (c, column) in table.columns.iter().enumerate() {
            let _ = write!(
                html,
                "<th{}>{}</th>",
                header_class(c),
                escape(&column.header)
            );
        }
        html.push_str("</tr>\n");
    }
    html.push_str("</thead>\n<tbody>\n");
    for row in &table.rows {
        html.push_str("<tr>");
        for cell in row {
            match cell {
                Cell::Text(text) => {
                    let _ = write!(html, "<td>{}</td>", escape(text));
                }
                Cell::Number { value, pointer } => {
                    let _ = write!(
                        html,
                        "<td class=\"num\" data-value=\"{value}\" data-pointer=\"{}\">{}</td>",
                        escape(pointer),
                        escape(&format_number(*value))
                    );
                }
                Cell::Empty => html.push_str("<td class=\"num\">–</td>"),
            }
        }
        html.push_str("</tr>\n");
    }
    html.push_str("</tbody>\n</table></div>\n");
    html
}

/// Links to a table's CSV and JSON files.
fn table_links(table: &Table) -> String {
    let info = table.info();
    format!(
        "<span class=\"links\">[<a href=\"{}\">CSV</a> · <a href=\"{}\">JSON</a>]</span>",
        escape(&info.csv),
        escape(&info.json)
    )
}

/// The whole page.
pub(crate) fn render_page(report: &StudyReport, sections: &[Section]) -> String {
    let mut html = String::new();
    let title = escape(&report.title);
    let _ = write!(
        html,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <title>{title}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n<main>\n<header>\n\
         <h1>{title}</h1>\n<p class=\"study\">Study <strong>{}</strong> · \
         <a href=\"report.json\">report.json</a> (every number of this page)</p>\n",
        escape(&report.study_name)
    );
    if !report.provenance.is_empty() {
        html.push_str("<dl class=\"provenance\">\n");
        for (key, value) in &report.provenance {
            let _ = writeln!(html, "<dt>{}</dt><dd>{}</dd>", escape(key), escape(value));
        }
        html.push_str("</dl>\n");
    }
    html.push_str("<nav><ol>\n");
    for section in sections {
        let _ = writeln!(
            html,
            "<li><a href=\"#{}\">{}</a></li>",
            section.id,
            escape(section.title)
        );
    }
    html.push_str("</ol></nav>\n</header>\n");

    let mut figure_number = 0;
    for section in sections {
        let _ = write!(
            html,
            "<section id=\"{}\">\n<h2>{}</h2>\n<p class=\"lead\">{}</p>\n",
            section.id,
            escape(section.title),
            escape(&section.text)
        );
        for figure in &section.figures {
            figure_number += 1;
            let info = &figure.info;
            let mut links = format!(
                "<a href=\"{}\">SVG</a> · <a href=\"{}\">PNG</a>",
                escape(&info.svg),
                escape(&info.png)
            );
            for table in &info.tables {
                let _ = write!(
                    links,
                    " · <a href=\"tables/{0}.csv\">{0}.csv</a>",
                    escape(table)
                );
            }
            let _ = write!(
                html,
                "<figure id=\"figure-{}\">\n<div class=\"svg\">{}</div>\n<figcaption><strong>Figure {figure_number}.</strong> {} \
                 <span class=\"links\">[{links}]</span></figcaption>\n</figure>\n",
                escape(&info.name),
                figure.svg,
                escape(&info.caption)
            );
        }
        for table in &section.tables {
            let _ = writeln!(
                html,
                "<h3 id=\"table-{}\">{} {}</h3>",
                escape(&table.name),
                escape(&table.title),
                table_links(table)
            );
            html.push_str(&render_table(table));
        }
        for table in &section.downloads {
            let _ = writeln!(
                html,
                "<p class=\"links\">{}: {}</p>",
                escape(&table.title),
                table_links(table)
            );
        }
        html.push_str("</section>\n");
    }
    let _ = write!(
        html,
        "<footer>Written by iuq-report {}. Figures are also available as SVG and PNG files, tables as CSV and JSON, \
         in the folders beside this page.</footer>\n</main>\n</body>\n</html>\n",
        env!("CARGO_PKG_VERSION")
    );
    html
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tables::Column;

    #[test]
    fn escaping_covers_markup() {
        assert_eq!(escape("a<b & \"c\""), "a&lt;b &amp; &quot;c&quot;");
    }

    #[test]
    fn grouped_tables_get_a_group_row_and_exact_values() {
        let table = Table {
            name: "t".into(),
            title: "T".into(),
            columns: vec![
                Column::plain("parameter"),
                Column::grouped("GP", "mean"),
                Column::grouped("GP", "std"),
            ],
            rows: vec![vec![
                Cell::text("k"),
                Cell::number(0.123456, "/a"),
                Cell::number(2.0, "/b"),
            ]],
        };
        let html = render_table(&table);
        assert!(html.contains("<th colspan=\"2\">GP</th>"));
        assert!(html.contains("data-value=\"0.123456\" data-pointer=\"/a\">0.1235</td>"));
        assert!(html.contains("<th rowspan=\"2\">parameter</th>"));
    }
}

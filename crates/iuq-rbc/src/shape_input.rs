//! Membrane shapes read back from viewers' files — legacy ASCII VTK polydata and ASCII PLY, as
//! [`crate::shape_output`] writes them (and ParaView or MeshLab save them): the vertices, in the
//! file's own unit. The functions take the text; reading files is the caller's business. Errors
//! are the reason, naming the line.

fn parse_number(token: &str, what: &str) -> Result<f64, String> {
    let v: f64 = token
        .parse()
        .map_err(|_| format!("{what}: `{token}` is not a number"))?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("{what}: `{token}` is not a finite number"))
    }
}

/// The points of a legacy ASCII VTK file (`POINTS n type` followed by 3n numbers).
pub fn vertices_from_vtk(text: &str) -> Result<Vec<[f64; 3]>, String> {
    let mut lines = text.lines().enumerate();
    match lines.next() {
        Some((_, l)) if l.starts_with("# vtk DataFile") => {}
        _ => return Err("bad header: not a legacy VTK file (`# vtk DataFile …`)".into()),
    }
    let _title = lines.next();
    match lines.next() {
        Some((_, l)) if l.trim().eq_ignore_ascii_case("ASCII") => {}
        Some((_, l)) if l.trim().eq_ignore_ascii_case("BINARY") => {
            return Err("binary VTK is not supported; write ASCII".into());
        }
        _ => return Err("bad header: the third line must be ASCII".into()),
    }
    let (line_no, count) = loop {
        let Some((i, line)) = lines.next() else {
            return Err("no POINTS section".into());
        };
        let mut words = line.split_whitespace();
        if words
            .next()
            .is_some_and(|w| w.eq_ignore_ascii_case("POINTS"))
        {
            let count = words
                .next()
                .and_then(|w| w.parse::<usize>().ok())
                .ok_or_else(|| format!("line {}: expected `POINTS n type`", i + 1))?;
            // Every coordinate takes at least one character of the file.
            if count
                .checked_mul(3)
                .is_none_or(|wanted| wanted > text.len())
            {
                return Err(format!(
                    "line {}: POINTS announces {count} points, more than the file holds",
                    i + 1
                ));
            }
            break (i + 1, count);
        }
    };
    let mut numbers = Vec::with_capacity(3 * count);
    for (i, line) in lines {
        if numbers.len() >= 3 * count {
            break;
        }
        for token in line.split_whitespace() {
            if numbers.len() >= 3 * count {
                break;
            }
            numbers.push(parse_number(token, &format!("line {}", i + 1))?);
        }
    }
    if numbers.len() < 3 * count {
        return Err(format!(
            "POINTS (line {line_no}) announces {count} points but only {} coordinates follow",
            numbers.len()
        ));
    }
    Ok(numbers
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect())
}

/// The vertices of an ASCII PLY file (`x`, `y`, `z` properties of the `vertex` element, which
/// must come first).
pub fn vertices_from_ply(text: &str) -> Result<Vec<[f64; 3]>, String> {
    let mut lines = text.lines().enumerate();
    match lines.next() {
        Some((_, l)) if l.trim() == "ply" => {}
        _ => return Err("bad header: not a PLY file (first line `ply`)".into()),
    }
    let mut ascii = false;
    let mut element: Option<String> = None;
    let mut first_element: Option<String> = None;
    let mut vertex_count = None;
    let mut properties: Vec<String> = Vec::new();
    loop {
        let Some((i, line)) = lines.next() else {
            return Err("bad header: no `end_header` line".into());
        };
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["end_header"] => break,
            ["format", "ascii", ..] => ascii = true,
            ["format", other, ..] => {
                return Err(format!(
                    "line {}: format `{other}` is not supported; write ASCII PLY",
                    i + 1
                ));
            }
            ["element", name, count] => {
                if first_element.is_none() {
                    first_element = Some((*name).to_string());
                }
                if *name == "vertex" {
                    vertex_count =
                        Some(count.parse::<usize>().map_err(|_| {
                            format!("line {}: `{count}` is not a vertex count", i + 1)
                        })?);
                }
                element = Some((*name).to_string());
            }
            ["property", .., name] if element.as_deref() == Some("vertex") => {
                properties.push((*name).to_string());
            }
            _ => {}
        }
    }
    if !ascii {
        return Err("bad header: no `format ascii 1.0` line".into());
    }
    let count = vertex_count.ok_or("bad header: no `element vertex n` line")?;
    if first_element.as_deref() != Some("vertex") {
        return Err("the `vertex` element must be the first element".into());
    }
    let mut index = [0usize; 3];
    for (slot, name) in index.iter_mut().zip(["x", "y", "z"]) {
        *slot = properties
            .iter()
            .position(|p| p == name)
            .ok_or_else(|| format!("bad header: the vertex element has no property `{name}`"))?;
    }
    // Every vertex takes at least one line of the file.
    if count > text.len() {
        return Err(format!(
            "the header announces {count} vertices, more than the file holds"
        ));
    }
    let mut vertices = Vec::with_capacity(count);
    for _ in 0..count {
        let Some((i, line)) = lines.next() else {
            return Err(format!(
                "the header announces {count} vertices but only {} follow",
                vertices.len()
            ));
        };
        let what = format!("line {}", i + 1);
        let tokens: Vec<&str> = line.split_whitespace().collect();
        if tokens.len() < properties.len() {
            return Err(format!(
                "{what}: {} values, the vertex element has {} properties",
                tokens.len(),
                properties.len()
            ));
        }
        vertices.push([
            parse_number(tokens[index[0]], &what)?,
            parse_number(tokens[index[1]], &what)?,
            parse_number(tokens[index[2]], &what)?,
        ]);
    }
    Ok(vertices)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shape_output::{to_ply, to_vtk};

    fn tetrahedron() -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
        (
            vec![
                [0.5, -1.25, 3.0],
                [1.0e-3, 0.0, 0.0],
                [0.0, 1.0 / 3.0, 0.0],
                [0.0, 0.0, 1e7],
            ],
            vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        )
    }

    #[test]
    fn vtk_and_ply_of_the_writers_read_back_exactly() {
        let (v, t) = tetrahedron();
        assert_eq!(vertices_from_vtk(&to_vtk(&t, &v, "tet")).unwrap(), v);
        assert_eq!(vertices_from_ply(&to_ply(&t, &v, "tet")).unwrap(), v);
    }

    #[test]
    fn truncated_and_malformed_shapes_are_reported() {
        let (v, t) = tetrahedron();
        let vtk = to_vtk(&t, &v, "tet");
        let cut: String = vtk.lines().take(6).collect::<Vec<_>>().join("\n");
        assert!(
            vertices_from_vtk(&cut)
                .unwrap_err()
                .contains("announces 4 points")
        );
        assert!(
            vertices_from_vtk(&vtk.replace("1e-3", "nan").replace("0.001", "nan"))
                .unwrap_err()
                .contains("not a finite number")
        );
        assert!(
            vertices_from_vtk("hello")
                .unwrap_err()
                .contains("bad header")
        );
        let ply = to_ply(&t, &v, "tet");
        assert!(
            vertices_from_ply(&ply.replace("ascii", "binary_little_endian"))
                .unwrap_err()
                .contains("not supported")
        );
        assert!(
            vertices_from_ply(&ply.replace("property double y", "property double w"))
                .unwrap_err()
                .contains("no property `y`")
        );
    }
}

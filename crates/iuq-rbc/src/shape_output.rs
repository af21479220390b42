//! Membrane shapes as text for viewers (ParaView, MeshLab, Blender): legacy VTK polydata and
//! ASCII PLY. The functions return strings; writing files is the caller's business.

use std::fmt::Write;

/// File formats for shapes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShapeFormat {
    /// Legacy VTK (`.vtk`, ASCII POLYDATA).
    Vtk,
    /// Stanford PLY (`.ply`, ASCII).
    Ply,
}

impl ShapeFormat {
    /// The file extension, without the dot.
    pub fn extension(self) -> &'static str {
        match self {
            ShapeFormat::Vtk => "vtk",
            ShapeFormat::Ply => "ply",
        }
    }

    /// The shape in this format.
    pub fn render(self, triangles: &[[usize; 3]], vertices: &[[f64; 3]], title: &str) -> String {
        match self {
            ShapeFormat::Vtk => to_vtk(triangles, vertices, title),
            ShapeFormat::Ply => to_ply(triangles, vertices, title),
        }
    }
}

/// Legacy VTK POLYDATA with the vertices as points and the triangles as polygons.
pub fn to_vtk(triangles: &[[usize; 3]], vertices: &[[f64; 3]], title: &str) -> String {
    let mut s = String::with_capacity(64 * (vertices.len() + triangles.len()));
    let title: String = title.chars().filter(|c| *c != '\n').take(255).collect();
    let _ = writeln!(
        s,
        "# vtk DataFile Version 3.0\n{title}\nASCII\nDATASET POLYDATA"
    );
    let _ = writeln!(s, "POINTS {} double", vertices.len());
    for v in vertices {
        let _ = writeln!(s, "{} {} {}", v[0], v[1], v[2]);
    }
    let _ = writeln!(s, "POLYGONS {} {}", triangles.len(), 4 * triangles.len());
    for t in triangles {
        let _ = writeln!(s, "3 {} {} {}", t[0], t[1], t[2]);
    }
    s
}

/// ASCII PLY with vertex coordinates and triangular faces.
pub fn to_ply(triangles: &[[usize; 3]], vertices: &[[f64; 3]], title: &str) -> String {
    let mut s = String::with_capacity(64 * (vertices.len() + triangles.len()));
    let title: String = title.chars().filter(|c| *c != '\n').collect();
    let _ = writeln!(
        s,
        "ply\nformat ascii 1.0\ncomment {title}\nelement vertex {}\nproperty double x\nproperty double y\nproperty double z\nelement face {}\nproperty list uchar int vertex_indices\nend_header",
        vertices.len(),
        triangles.len()
    );
    for v in vertices {
        let _ = writeln!(s, "{} {} {}", v[0], v[1], v[2]);
    }
    for t in triangles {
        let _ = writeln!(s, "3 {} {} {}", t[0], t[1], t[2]);
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_have_their_headers_and_counts() {
        let v = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        let t = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
        let vtk = to_vtk(&t, &v, "tet");
        assert!(vtk.starts_with("# vtk DataFile Version 3.0\ntet\nASCII\nDATASET POLYDATA"));
        assert!(vtk.contains("POINTS 4 double") && vtk.contains("POLYGONS 4 16"));
        let ply = to_ply(&t, &v, "tet");
        assert!(ply.contains("element vertex 4") && ply.contains("element face 4"));
        assert_eq!(ply.lines().count(), 10 + 4 + 4);
    }
}

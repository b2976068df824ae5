//! The dataset's Parquet tables through Arrow: the frames (`data/`), the episodes
//! (`meta/episodes/`) and the tasks (`meta/tasks.parquet`), in the column types LeRobot's loader
//! casts them to (a feature of shape `[1]` is a plain column, `[n]` a fixed-size list of `n`).
//! Snappy-compressed, one row group per episode in the frames file.

use super::{io_err, ExportError};
use arrow_array::builder::{ListBuilder, StringBuilder};
use arrow_array::{
    ArrayRef, BooleanArray, FixedSizeListArray, Float32Array, Float64Array, Int64Array,
    RecordBatch, StringArray,
};
use arrow_schema::{DataType, Field, Schema};
use parquet::arrow::ArrowWriter;
use parquet::basic::Compression;
use parquet::file::properties::WriterProperties;
use std::path::Path;
use std::sync::Arc;

/// A column of one table: its values for every row.
#[derive(Debug, Clone, PartialEq)]
pub enum Column {
    F32(Vec<f32>),
    F64(Vec<f64>),
    I64(Vec<i64>),
    Bool(Vec<bool>),
    /// Nullable strings.
    Str(Vec<Option<String>>),
    /// Fixed-size lists of `n` (the values row after row).
    F32s(usize, Vec<f32>),
    F64s(usize, Vec<f64>),
    /// A list of strings per row (the episodes' `tasks`).
    StrLists(Vec<Vec<String>>),
}

impl Column {
    fn rows(&self) -> usize {
        match self {
            Column::F32(v) => v.len(),
            Column::F64(v) => v.len(),
            Column::I64(v) => v.len(),
            Column::Bool(v) => v.len(),
            Column::Str(v) => v.len(),
            Column::F32s(n, v) => v.len() / (*n).max(1),
            Column::F64s(n, v) => v.len() / (*n).max(1),
            Column::StrLists(v) => v.len(),
        }
    }

    fn slice(&self, from: usize, to: usize) -> Column {
        match self {
            Column::F32(v) => Column::F32(v[from..to].to_vec()),
            Column::F64(v) => Column::F64(v[from..to].to_vec()),
            Column::I64(v) => Column::I64(v[from..to].to_vec()),
            Column::Bool(v) => Column::Bool(v[from..to].to_vec()),
            Column::Str(v) => Column::Str(v[from..to].to_vec()),
            Column::F32s(n, v) => Column::F32s(*n, v[from * n..to * n].to_vec()),
            Column::F64s(n, v) => Column::F64s(*n, v[from * n..to * n].to_vec()),
            Column::StrLists(v) => Column::StrLists(v[from..to].to_vec()),
        }
    }

    fn field(&self, name: &str) -> Field {
        let list = |t: DataType, n: &usize| {
            DataType::FixedSizeList(Arc::new(Field::new_list_field(t, true)), *n as i32)
        };
        let (t, nullable) = match self {
            Column::F32(_) => (DataType::Float32, false),
            Column::F64(_) => (DataType::Float64, false),
            Column::I64(_) => (DataType::Int64, false),
            Column::Bool(_) => (DataType::Boolean, false),
            Column::Str(_) => (DataType::Utf8, true),
            Column::F32s(n, _) => (list(DataType::Float32, n), false),
            Column::F64s(n, _) => (list(DataType::Float64, n), false),
            Column::StrLists(_) => {
                (DataType::List(Arc::new(Field::new_list_field(DataType::Utf8, true))), false)
            }
        };
        Field::new(name, t, nullable)
    }

    fn array(&self) -> Result<ArrayRef, arrow_schema::ArrowError> {
        let fixed = |t: DataType, n: &usize, values: ArrayRef| {
            FixedSizeListArray::try_new(
                Arc::new(Field::new_list_field(t, true)),
                *n as i32,
                values,
                None,
            )
            .map(|a| Arc::new(a) as ArrayRef)
        };
        Ok(match self {
            Column::F32(v) => Arc::new(Float32Array::from(v.clone())),
            Column::F64(v) => Arc::new(Float64Array::from(v.clone())),
            Column::I64(v) => Arc::new(Int64Array::from(v.clone())),
            Column::Bool(v) => Arc::new(BooleanArray::from(v.clone())),
            Column::Str(v) => Arc::new(StringArray::from(v.clone())),
            Column::F32s(n, v) => {
                fixed(DataType::Float32, n, Arc::new(Float32Array::from(v.clone())))?
            }
            Column::F64s(n, v) => {
                fixed(DataType::Float64, n, Arc::new(Float64Array::from(v.clone())))?
            }
            Column::StrLists(v) => {
                let mut b = ListBuilder::new(StringBuilder::new());
                for row in v {
                    row.iter().for_each(|s| b.values().append_value(s));
                    b.append(true);
                }
                Arc::new(b.finish())
            }
        })
    }
}

/// A table: named columns of equal length, and the row ranges that become row groups.
#[derive(Debug, Clone, Default)]
pub struct Table {
    pub columns: Vec<(String, Column)>,
    /// Schema metadata (e.g. `pandas` for the tasks table).
    pub metadata: Vec<(String, String)>,
}

impl Table {
    pub fn push(&mut self, name: &str, c: Column) {
        self.columns.push((name.to_string(), c));
    }

    pub fn rows(&self) -> usize {
        self.columns.first().map_or(0, |(_, c)| c.rows())
    }

    fn schema(&self) -> Schema {
        let fields: Vec<Field> = self.columns.iter().map(|(n, c)| c.field(n)).collect();
        let meta: std::collections::HashMap<String, String> =
            self.metadata.iter().cloned().collect();
        Schema::new(fields).with_metadata(meta)
    }

    fn batch(&self, schema: &Arc<Schema>, from: usize, to: usize) -> Result<RecordBatch, String> {
        let arrays = self
            .columns
            .iter()
            .map(|(_, c)| c.slice(from, to).array())
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| e.to_string())?;
        RecordBatch::try_new(schema.clone(), arrays).map_err(|e| e.to_string())
    }

    /// Write the table to `path`, one row group per range of `groups` (all rows in one group
    /// when empty).
    pub fn write(&self, path: &Path, groups: &[(usize, usize)]) -> Result<(), ExportError> {
        let n = self.rows();
        if let Some((name, _)) = self.columns.iter().find(|(_, c)| c.rows() != n) {
            return Err(ExportError::Io(format!(
                "{}: column {name} has a different length (an export bug)",
                path.display()
            )));
        }
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir).map_err(|e| io_err("cannot create", dir, e))?;
        }
        let file = std::fs::File::create(path).map_err(|e| io_err("cannot create", path, e))?;
        let schema = Arc::new(self.schema());
        let props = WriterProperties::builder().set_compression(Compression::SNAPPY).build();
        let fail = |e: &dyn std::fmt::Display| io_err("cannot write", path, e);
        let mut w =
            ArrowWriter::try_new(file, schema.clone(), Some(props)).map_err(|e| fail(&e))?;
        let all = [(0, n)];
        for &(from, to) in if groups.is_empty() { &all[..] } else { groups } {
            let b = self.batch(&schema, from, to).map_err(|e| fail(&e))?;
            w.write(&b).map_err(|e| fail(&e))?;
            w.flush().map_err(|e| fail(&e))?;
        }
        w.close().map_err(|e| fail(&e))?;
        Ok(())
    }
}

/// The tasks table as pandas writes LeRobot's: `task_index` and the task text as the index
/// (named `task`), which the `pandas` schema metadata says so the loader can look tasks up by text.
pub fn tasks_table(tasks: &[String]) -> Table {
    let mut t = Table::default();
    t.push("task_index", Column::I64((0..tasks.len() as i64).collect()));
    t.push("task", Column::Str(tasks.iter().cloned().map(Some).collect()));
    let pandas = serde_json::json!({
        "index_columns": ["task"],
        "column_indexes": [{"name": null, "field_name": null, "pandas_type": "unicode",
                            "numpy_type": "object", "metadata": {"encoding": "UTF-8"}}],
        "columns": [
            {"name": "task_index", "field_name": "task_index", "pandas_type": "int64",
             "numpy_type": "int64", "metadata": null},
            {"name": "task", "field_name": "task", "pandas_type": "unicode",
             "numpy_type": "object", "metadata": null}
        ],
        "creator": {"library": "hitl", "version": env!("CARGO_PKG_VERSION")},
        "pandas_version": "2.2.3"
    });
    t.metadata.push(("pandas".into(), pandas.to_string()));
    t
}

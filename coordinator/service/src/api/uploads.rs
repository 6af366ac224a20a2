//! The datasets and FMUs a client uploads: their chunks joined, the file checked and kept,
//! and the lookup of one by the id its upload answered.

use super::messages::fmu_message;
use super::CalibrationApi;
use crate::hosting::datasets::DatasetInfo;
use crate::hosting::fmus::FmuInfo;
use calib_engine::limits::{MAX_CHUNK_BYTES, MAX_DATASET_BYTES, MAX_FMU_BYTES};
use calib_proto::v1 as pb;
use tonic::{Status, Streaming};

impl CalibrationApi {
    /// The end of `UploadDataset`, once the chunks are joined: check the file's name, parse
    /// and keep it. The web app's upload route, which receives the file whole, calls it too.
    pub async fn upload(
        &self,
        file_name: String,
        mut time_column: String,
        bytes: Vec<u8>,
    ) -> Result<pb::Dataset, Status> {
        if file_name.is_empty() {
            return Err(Status::invalid_argument(
                "file_name: the first chunk must name the file (its extension picks the parser)",
            ));
        }
        if bytes.is_empty() {
            return Err(Status::invalid_argument("data: the file is empty"));
        }
        let guessed = time_column.trim().is_empty();
        if guessed {
            time_column.clear();
        }
        let campaigns = self.campaigns.clone();
        let info = self
            .blocking(move || campaigns.datasets().put(&file_name, &time_column, &bytes))
            .await?;
        Ok(pb::Dataset {
            id: info.id,
            columns: info.columns,
            samples: info.samples as u64,
            start_time: info.start_time,
            stop_time: info.stop_time,
            time_column: info.time_column,
            time_column_guessed: guessed,
        })
    }

    /// The end of `UploadFmu`, once the chunks are joined: check the archive and keep it.
    /// The web app's upload route, which receives the file whole, calls it too.
    pub async fn upload_fmu_bytes(
        &self,
        file_name: String,
        bytes: Vec<u8>,
    ) -> Result<pb::Fmu, Status> {
        if file_name.is_empty() {
            return Err(Status::invalid_argument(
                "file_name: the first chunk must name the file (e.g. Model.fmu)",
            ));
        }
        if bytes.is_empty() {
            return Err(Status::invalid_argument("data: the file is empty"));
        }
        let campaigns = self.campaigns.clone();
        let info = self
            .blocking(move || campaigns.fmus()?.put(&file_name, &bytes))
            .await?;
        Ok(fmu_message(&info))
    }

    /// The uploaded FMU `id`, or NOT_FOUND.
    pub(super) async fn fmu(&self, id: &str, field: &str) -> Result<FmuInfo, Status> {
        let campaigns = self.campaigns.clone();
        let found = {
            let id = id.to_string();
            self.blocking(move || campaigns.fmus()?.get(&id)).await?
        };
        found.ok_or_else(|| {
            Status::not_found(format!(
                "{field}: no FMU `{id}` on this coordinator; upload it with UploadFmu"
            ))
        })
    }

    /// The uploaded dataset `id`, named by the message's `field`; NOT_FOUND when absent.
    pub(super) async fn dataset(&self, id: &str, field: &str) -> Result<DatasetInfo, Status> {
        if id.is_empty() {
            return Err(Status::invalid_argument(format!(
                "{field}: missing; upload the data with UploadDataset first"
            )));
        }
        let found = {
            let campaigns = self.campaigns.clone();
            let id = id.to_string();
            self.blocking(move || campaigns.datasets().get(&id)).await?
        };
        found.ok_or_else(|| {
            Status::not_found(format!(
                "{field}: no dataset `{id}` on this coordinator; upload it with UploadDataset"
            ))
        })
    }
}

/// The chunks of an `UploadDataset` joined: the file's name and time column (the first
/// chunk's) and its bytes, refused past [`MAX_CHUNK_BYTES`] a chunk or
/// [`MAX_DATASET_BYTES`] in all.
pub(super) async fn dataset_chunks(
    mut chunks: Streaming<pb::DatasetChunk>,
) -> Result<(String, String, Vec<u8>), Status> {
    let mut bytes = Vec::new();
    let (mut file_name, mut time_column) = (String::new(), String::new());
    let mut first = true;
    while let Some(chunk) = chunks.message().await? {
        if first {
            file_name = chunk.file_name;
            time_column = chunk.time_column;
            first = false;
        }
        append_chunk(&mut bytes, &chunk.data, MAX_DATASET_BYTES, || {
            format!("data: the file is more than the {MAX_DATASET_BYTES} bytes accepted")
        })?;
    }
    Ok((file_name, time_column, bytes))
}

/// The chunks of an `UploadFmu` joined: the archive's name (the first chunk's) and its
/// bytes, refused past [`MAX_CHUNK_BYTES`] a chunk or [`MAX_FMU_BYTES`] in all.
pub(super) async fn fmu_chunks(
    mut chunks: Streaming<pb::FmuChunk>,
) -> Result<(String, Vec<u8>), Status> {
    let mut bytes = Vec::new();
    let mut file_name = String::new();
    let mut first = true;
    while let Some(chunk) = chunks.message().await? {
        if first {
            file_name = chunk.file_name;
            first = false;
        }
        append_chunk(&mut bytes, &chunk.data, MAX_FMU_BYTES, || {
            format!(
                "fmu: the archive is more than the {MAX_FMU_BYTES} bytes accepted (what a \
                 worker's UploadFmu carries)"
            )
        })?;
    }
    Ok((file_name, bytes))
}

/// Append one chunk's `data` to `bytes`: refused past [`MAX_CHUNK_BYTES`] a chunk, or past
/// `limit` in all (`too_large` says so in the upload's words).
fn append_chunk(
    bytes: &mut Vec<u8>,
    data: &[u8],
    limit: usize,
    too_large: impl FnOnce() -> String,
) -> Result<(), Status> {
    if data.len() > MAX_CHUNK_BYTES {
        return Err(Status::invalid_argument(format!(
            "data: a chunk of {} bytes is more than the {MAX_CHUNK_BYTES} accepted",
            data.len()
        )));
    }
    if bytes.len() + data.len() > limit {
        return Err(Status::invalid_argument(too_large()));
    }
    bytes.extend_from_slice(data);
    Ok(())
}

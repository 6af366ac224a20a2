//! The datasets and FMUs a client uploads: the end of their uploads, once the chunks are
//! joined, and the lookup of one by the id its upload answered.

use super::messages::fmu_message;
use super::CalibrationApi;
use crate::campaigns::datasets::DatasetInfo;
use crate::campaigns::fmus::FmuInfo;
use calib_proto::v1 as pb;
use tonic::Status;

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

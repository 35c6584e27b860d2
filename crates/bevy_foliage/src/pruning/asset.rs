//! `*.foliage` files as Bevy assets: [`BakedFoliageLoader`] reads them through the `AssetServer`
//! with the decoder of [`super::format`].

use super::bake::BakedFoliage;
use super::format::{FormatError, decode};

/// Loads `*.foliage` files into [`BakedFoliage`] assets; a corrupt or mismatched file fails the
/// load with a [`FormatError`] (the asset's load state becomes `Failed`), never a panic.
#[derive(Default, bevy::reflect::TypePath)]
pub struct BakedFoliageLoader;

impl bevy::asset::AssetLoader for BakedFoliageLoader {
    type Asset = BakedFoliage;
    type Settings = ();
    type Error = FormatError;

    async fn load(
        &self,
        reader: &mut dyn bevy::asset::io::Reader,
        _settings: &(),
        load_context: &mut bevy::asset::LoadContext<'_>,
    ) -> Result<BakedFoliage, FormatError> {
        let mut bytes = Vec::new();
        reader
            .read_to_end(&mut bytes)
            .await
            .map_err(|e| FormatError::Io(format!("{}: {e}", load_context.path())))?;
        decode(&bytes)
    }

    fn extensions(&self) -> &[&str] {
        &["foliage"]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pruning::format::tests::sample;
    use crate::pruning::format::{encode, save};

    #[test]
    fn asset_server_loads_good_files_and_fails_corrupt_ones_without_panicking() {
        use bevy::asset::{AssetPlugin, AssetServer, Assets, LoadState};
        use bevy::prelude::*;
        let dir = std::env::temp_dir().join(format!("foliage-assets-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let good = sample();
        save(&good, &dir.join("good.foliage")).unwrap();
        let mut corrupt = encode(&good);
        let middle = corrupt.len() / 2;
        corrupt[middle] ^= 0xFF;
        std::fs::write(dir.join("corrupt.foliage"), corrupt).unwrap();

        let mut app = App::new();
        app.add_plugins((
            MinimalPlugins,
            AssetPlugin {
                file_path: dir.to_string_lossy().into_owned(),
                ..default()
            },
        ))
        .init_asset::<BakedFoliage>()
        .init_asset_loader::<BakedFoliageLoader>();
        let server = app.world().resource::<AssetServer>().clone();
        let good_handle: Handle<BakedFoliage> = server.load("good.foliage");
        let corrupt_handle: Handle<BakedFoliage> = server.load("corrupt.foliage");
        let settled = |s: LoadState| matches!(s, LoadState::Loaded | LoadState::Failed(_));
        for _ in 0..500 {
            app.update();
            if settled(server.load_state(&good_handle))
                && settled(server.load_state(&corrupt_handle))
            {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
        assert!(matches!(server.load_state(&good_handle), LoadState::Loaded));
        assert_eq!(
            app.world()
                .resource::<Assets<BakedFoliage>>()
                .get(&good_handle),
            Some(&good)
        );
        match server.load_state(&corrupt_handle) {
            LoadState::Failed(e) => assert!(e.to_string().contains("corrupt"), "{e}"),
            other => panic!("corrupt file should fail to load, got {other:?}"),
        }
        std::fs::remove_dir_all(dir).unwrap();
    }
}

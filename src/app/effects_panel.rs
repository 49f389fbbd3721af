//! The effects panel: the catalogue of physical effects the paper's model
//! lacks, switched on and off live.

use crate::effects;

use super::GyropathApp;

impl GyropathApp {
    /// The effect catalogue as checkboxes; whether the model changed.
    pub(super) fn effects_ui(&mut self, ui: &mut egui::Ui) -> bool {
        let fit = &mut self.settings.fit;
        let mut changed = false;
        ui.heading("Effects");
        ui.label("The paper's model is always on; add effects it lacks:");
        let offered = self
            .ride
            .as_ref()
            .map_or_else(|| effects::catalogue(&[]), |r| r.offered_effects.clone());
        for (id, about) in offered {
            let mut on = effects_contains(&fit.model.effects, &id);
            if ui.checkbox(&mut on, &id).on_hover_text(about).changed() {
                set_effect(&mut fit.model.effects, &id, on);
                changed = true;
            }
        }
        changed
    }
}

pub(super) fn effects_contains(list: &[String], id: &str) -> bool {
    list.iter().any(|e| e.split(',').any(|p| p.trim() == id))
}

pub(super) fn set_effect(list: &mut Vec<String>, id: &str, on: bool) {
    if on {
        if !effects_contains(list, id) {
            list.push(id.to_string());
        }
    } else {
        list.retain(|e| e.trim() != id);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn effect_toggles_edit_the_list() {
        let mut list = vec!["paper".to_string()];
        set_effect(&mut list, "gyro_scale", true);
        set_effect(&mut list, "gyro_scale", true);
        assert_eq!(list, ["paper", "gyro_scale"]);
        assert!(effects_contains(&list, "gyro_scale"));
        set_effect(&mut list, "gyro_scale", false);
        assert_eq!(list, ["paper"]);
    }
}

"""Regenerate the bundled 3D-printing survey from printing_survey.toml:
part.stl, printing_survey.xml, truth_support.csv and the two synthetic response files."""

from simfab.crowd.survey import make_bundle

if __name__ == "__main__":
    print(make_bundle())

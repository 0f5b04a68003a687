"""The public API, frozen (pyhf's test_public_api): each public name of ``skinfit`` with its
signature (functions), bases (exceptions) or constructor and public members (classes). A
change here is a deliberate decision: update FROZEN with it, and CHANGELOG.md and docs/api.md."""

import inspect

import pytest

import skinfit

FROZEN = {
    'ConvergenceWarning': 'exception(UserWarning)',
    'Dataset': "class(id: 'str', title: 'str', frame: 'pd.DataFrame', columns: 'tuple', groups: 'tuple', provenance: 'MappingProxyType', model: 'str | None', path: 'str', sha256: 'str', card_file: 'str' = '', data_file: 'str' = '', data_sha256: 'str' = '') -> None card_file column data_file data_sha256 from_frame subset units with_observations",
    'Fit': 'class(idata, posterior=None, *, pointwise=None, stored=None, path=None) attr attrs complete content_hash converged dataset_id diagnostics group idata inputs map model_id notes partial_tree path pending posterior report_text save summary summary_stored warnings',
    'ForwardError': 'exception(InputError)',
    'InputError': 'exception(Portable, ValueError)',
    'InputTypeError': 'exception(InputError, TypeError)',
    'IntegrityWarning': 'exception(UserWarning)',
    'MisfitWarning': 'exception(UserWarning)',
    'MissingDependency': 'exception(Portable, ImportError)',
    'Model': "class(id: 'str', title: 'str', source: 'str', forward_ref: 'str', observables: 'tuple', covariates: 'tuple', parameters: 'tuple', constants: 'MappingProxyType', constant_sources: 'MappingProxyType', variants: 'tuple' = (), support: 'str' = '', split: 'MappingProxyType' = <factory>, plot: 'MappingProxyType' = <factory>, shear: 'MappingProxyType' = <factory>, linear: 'tuple' = (), shift: 'MappingProxyType' = <factory>, product: 'MappingProxyType' = <factory>, derived: 'MappingProxyType' = <factory>, path: 'str' = '', sha256: 'str' = '', card_text: 'str' = '', file: 'str' = '', user_function: 'bool' = False, function_sha256: 'str' = '', saved: 'bool' = False, function: 'object' = None) -> None card_text covariate_names derive evaluate file forward from_function function function_sha256 linear observable_names parameter_names path predict saved sha256 support to_card user_function variants",
    'PopulationResult': "class(model_id: 'str', parameters: 'list', families: 'list', subjects: 'list', mu: 'np.ndarray', sd: 'np.ndarray', corr: 'np.ndarray | None', shrunk: 'np.ndarray', separate: 'dict', hyperpriors: 'dict', sampler: 'dict' = <factory>, warnings: 'list' = <factory>, contraction: 'dict' = <factory>, inputs: 'dict' = <factory>, origin: 'str' = '') -> None contrast converged coordinates diagnostics effect effects get log origin population_draws predictive problems save subject_summary summary to_datatree",
    'PopulationWarning': 'exception(UserWarning)',
    'PriorSet': "class(id: 'str', model: 'str', priors: 'MappingProxyType', path: 'str' = '', sha256: 'str' = '', text: 'str' = '', file: 'str' = '') -> None file names path sha256 text",
    'RawSeriesWarning': 'exception(MisfitWarning)',
    'ShadowWarning': 'exception(UserWarning)',
    'SupportWarning': 'exception(UserWarning)',
    'WorkerError': 'exception(Portable, RuntimeError)',
    'compare': "(fits: 'Sequence[Fit] | Mapping[str, Fit]', *, method: 'str' = 'bridge', rng: 'int | np.random.Generator | None' = None) -> 'pd.DataFrame'",
    'design': "(fit_or_model: 'str | Model | Fit', candidates: 'str | os.PathLike | Mapping', n: 'int' = 24, params: 'Sequence[str] | None' = None, rng: 'int | np.random.Generator | None' = None, *, discriminate: 'Sequence[str | Model]' = (), baseline: 'str | os.PathLike | pd.DataFrame | None' = None, noise_scale: 'float | None' = None, priors: 'str | os.PathLike | PriorSet | Mapping | None' = None, n_outer: 'int' = 400, n_inner: 'int' = 400, n_batch: 'int' = 200, n_draws: 'int' = 4000) -> 'DesignResult'",
    'evidence': "(fit: 'Fit', method: 'str' = 'bridge', *, rng: 'int | np.random.Generator | None' = None, n_repeats: 'int' = 1, refresh: 'bool' = False, **options) -> 'LogEvidence'",
    'fit': "(model: 'str | Model', dataset: 'str | os.PathLike | Dataset | pd.DataFrame', priors: 'str | os.PathLike | PriorSet | Mapping | None' = None, *, units: 'Mapping[str, str] | None' = None, columns: 'Mapping[str, str] | None' = None, rng: 'int | np.random.Generator | None' = None, split: 'Mapping[str, Sequence[str]] | None' = None, noise: 'str | Mapping[str, str] | None' = None, constants: 'Mapping[str, float] | None' = None, nwalkers: 'int | None' = None, ess_target: 'float' = 400, max_steps: 'int' = 20000, progress: 'bool' = False, strict: 'bool' = False, n_global: 'int' = 2000, n_local: 'int' = 4, n_prior_draws: 'int' = 2000, checkpoint: 'str | os.PathLike | None' = None, resume: 'bool' = False, checkpoint_every: 'float' = 30.0, complete: 'bool' = True) -> 'Fit'",
    'fit_by': '(model, dataset, by, out_dir, *, priors=None, seed=None, split=None, noise=None, progress=False, ess_target=400, max_steps=20000, overwrite=False, writes_card=False, **fit_options)',
    'fit_contrasts': "(fits: 'Mapping[str, Fit]', parameter: 'str', rng: 'int | np.random.Generator | None' = None, prob: 'float' = 0.94, rope=None) -> 'pd.DataFrame'",
    'level_contrasts': "(fit: 'Fit', parameter: 'str', prob: 'float' = 0.94, rope=None) -> 'pd.DataFrame'",
    'ingest': "(files: 'str | os.PathLike | Sequence[str | os.PathLike]', rig: 'str | os.PathLike', out: 'str | os.PathLike | None' = None, *, review: 'bool' = False) -> 'Dataset'",
    'list_datasets': "() -> 'list[str]'",
    'list_models': "() -> 'list[str]'",
    'list_priors': "() -> 'list[str]'",
    'load_dataset': "(name: 'str | os.PathLike', *, model: 'str | Model | None' = None, units: 'Mapping[str, str] | None' = None, columns: 'Mapping[str, str] | None' = None, max_bytes: 'int | None' = None) -> 'Dataset'",
    'load_fit': "(path: 'str | os.PathLike') -> 'Fit'",
    'load_groups': "(path: 'str | os.PathLike') -> 'dict[str, Fit]'",
    'load_model': "(name: 'str | os.PathLike') -> 'Model'",
    'load_population': '(path)',
    'load_priors': "(name: 'str | os.PathLike', *, check_mass: 'bool' = True) -> 'PriorSet'",
    'population': "(fits: 'Mapping[str, Fit] | Sequence[Fit] | str | os.PathLike', parameters: 'Sequence[str] | None' = None, *, family: 'str | Mapping[str, str] | None' = None, correlated: 'bool' = False, method: 'str' = 'gibbs', rng: 'int | np.random.Generator | None' = None, model: 'str | None' = None, chains: 'int' = 8, ess_target: 'float' = 400, rhat_max: 'float' = 1.01, max_sweeps: 'int' = 20000, burn: 'int' = 300, min_contraction: 'float' = 0.5, n_draws: 'int' = 1000, max_steps: 'int' = 20000, cache: 'str | os.PathLike | None' = None) -> 'PopulationResult'",
    'population_tables': '(result, prob=0.94)',
    'run_sbc': '(model, dataset=None, *, priors=None, fit_priors=None, n_sims=100, n_draws=99, seed=0, n_rows=None, split=None, ess_target=100, max_steps=4000, n_global=300, alpha=0.01, jobs=1, progress=None)',
    'truncate': "(dist, lower: 'float', upper: 'float') -> 'Truncated'",
}


def describe(obj):
    """What FROZEN records of one public object."""
    if inspect.isclass(obj) and issubclass(obj, BaseException):
        return "exception(" + ", ".join(b.__name__ for b in obj.__bases__) + ")"
    if inspect.isclass(obj):
        members = {n for n in vars(obj) if not n.startswith("_")}
        for base in obj.__mro__[1:]:
            if base.__module__.startswith("skinfit"):
                members |= {n for n in vars(base) if not n.startswith("_")}
        return f"class{inspect.signature(obj)} " + " ".join(sorted(members))
    return f"{inspect.signature(obj)}"


def test_public_names_are_the_frozen_ones():
    assert sorted(skinfit.__all__) == sorted(FROZEN)
    assert set(dir(skinfit)) >= set(FROZEN)


@pytest.mark.parametrize("name", sorted(FROZEN))
def test_public_signature_is_the_frozen_one(name):
    assert describe(getattr(skinfit, name)) == FROZEN[name]


def test_negative_control_a_changed_signature_or_member_is_seen():
    def fit(model, dataset, priors=None, *, rng=None):  # a keyword dropped
        pass

    class Fit(skinfit.Fit):
        def extra(self):  # a public member added
            pass

    assert describe(fit) != FROZEN["fit"]
    assert describe(Fit) != FROZEN["Fit"]
    with pytest.raises(AttributeError, match="has no attribute 'fitt'"):
        skinfit.fitt

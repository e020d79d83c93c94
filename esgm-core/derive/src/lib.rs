//! `#[derive(Entity)]` for esgm: a plain struct with named fields becomes an entity
//! structure type, with conversions both ways.
//!
//! Generated code names `::esgm_core::…` paths only, so the macro works from any crate
//! that depends on esgm-core (and inside esgm-core, which aliases itself).
//!
//! Attributes:
//! - `#[entity(name = "TypeName")]` on the struct: the registered type name (default:
//!   the struct's identifier).
//! - `#[entity(rename = "attr")]` on a field: the attribute name (default: the field's
//!   identifier).
#![deny(missing_docs)]

use proc_macro::TokenStream;
use quote::quote;
use syn::{Data, DeriveInput, Fields, LitStr, parse_macro_input, spanned::Spanned};

/// Implements `esgm_core::Entity` for a struct with named fields whose types implement
/// `esgm_core::AttributeField`.
#[proc_macro_derive(Entity, attributes(entity))]
pub fn derive_entity(input: TokenStream) -> TokenStream {
    let input = parse_macro_input!(input as DeriveInput);
    expand(&input).unwrap_or_else(|e| e.to_compile_error()).into()
}

fn entity_attr(attrs: &[syn::Attribute], key: &str) -> syn::Result<Option<String>> {
    let mut found = None;
    for attr in attrs.iter().filter(|a| a.path().is_ident("entity")) {
        attr.parse_nested_meta(|meta| {
            if meta.path.is_ident(key) {
                let lit: LitStr = meta.value()?.parse()?;
                found = Some(lit.value());
                Ok(())
            } else {
                Err(meta.error(format!("unknown entity attribute, expected `{key} = \"…\"`")))
            }
        })?;
    }
    Ok(found)
}

fn expand(input: &DeriveInput) -> syn::Result<proc_macro2::TokenStream> {
    let ident = &input.ident;
    let Data::Struct(data) = &input.data else {
        return Err(syn::Error::new(input.span(), "#[derive(Entity)] needs a struct"));
    };
    let Fields::Named(fields) = &data.fields else {
        return Err(syn::Error::new(input.span(), "#[derive(Entity)] needs named fields"));
    };
    if !input.generics.params.is_empty() {
        return Err(syn::Error::new(
            input.generics.span(),
            "#[derive(Entity)] needs a non-generic struct",
        ));
    }
    let type_name = entity_attr(&input.attrs, "name")?.unwrap_or_else(|| ident.to_string());

    let vis = &input.vis;
    let view = quote::format_ident!("{}View", ident);
    let view_doc = format!(
        "A typed view of a `{type_name}` structure, read in place (see \
         `esgm_core::entity_view`): made by [`{ident}::view`]."
    );
    let make_doc = format!(
        "Reads a `{type_name}` structure in place: an archived one (shared memory, a \
         file) without decoding it, or an owned one or a sample. Every attribute is \
         found and checked once, here."
    );
    let mut attrs = Vec::new();
    let mut to = Vec::new();
    let mut from = Vec::new();
    let mut view_fields = Vec::new();
    let mut view_reads = Vec::new();
    let mut view_getters = Vec::new();
    for f in &fields.named {
        let Some(fid) = f.ident.as_ref() else { continue };
        let ty = &f.ty;
        let name = entity_attr(&f.attrs, "rename")?.unwrap_or_else(|| fid.to_string());
        let getter_doc = format!("Attribute `{name}`.");
        view_fields.push(quote! {
            #fid: <#ty as ::esgm_core::ViewField>::View<'a>
        });
        view_reads.push(quote! {
            #fid: ::esgm_core::view_field::<#ty>(source, #type_name, #name)?
        });
        view_getters.push(quote! {
            #[doc = #getter_doc]
            #vis fn #fid(&self) -> <#ty as ::esgm_core::ViewField>::View<'a> {
                ::std::clone::Clone::clone(&self.#fid)
            }
        });
        attrs.push(quote! {
            ::esgm_core::Attr {
                name: ::std::string::String::from(#name),
                sort: <#ty as ::esgm_core::AttributeField>::SORT,
                element_type: <#ty as ::esgm_core::AttributeField>::element_type()
                    .map(::std::string::String::from),
            }
        });
        to.push(quote! {
            ::esgm_core::AttributeValuePair {
                name: ::std::string::String::from(#name),
                value: ::esgm_core::AttributeField::to_value(&self.#fid),
            }
        });
        from.push(quote! {
            #fid: ::esgm_core::entity::read_field::<#ty>(attributes, #type_name, #name)?
        });
    }

    Ok(quote! {
        impl ::esgm_core::Entity for #ident {
            const TYPE_NAME: &'static str = #type_name;

            fn entity_structure_type() -> ::esgm_core::EntityStructureType {
                ::esgm_core::EntityStructureType {
                    name: ::std::string::String::from(#type_name),
                    attributes: ::std::vec![#(#attrs),*],
                }
            }

            fn to_attributes(&self) -> ::std::vec::Vec<::esgm_core::AttributeValuePair> {
                ::std::vec![#(#to),*]
            }

            fn from_attribute_refs(
                attributes: ::esgm_core::Attributes<'_>,
            ) -> ::std::result::Result<Self, ::esgm_core::FromEntityError> {
                let attributes = &attributes;
                ::std::result::Result::Ok(Self { #(#from),* })
            }
        }

        #[doc = #view_doc]
        #[derive(Clone)]
        #vis struct #view<'a> {
            #(#view_fields),*
        }

        impl<'a> #view<'a> {
            #(#view_getters)*
        }

        impl #ident {
            #[doc = #make_doc]
            #vis fn view<'a>(
                source: impl ::std::convert::Into<::esgm_core::ViewSource<'a>>,
            ) -> ::std::result::Result<#view<'a>, ::esgm_core::ViewError> {
                let source = source.into();
                ::std::result::Result::Ok(#view { #(#view_reads),* })
            }
        }

        /// A typed entity nested in another is decoded once when a view is made.
        impl ::esgm_core::ViewField for #ident {
            type View<'a> = ::std::sync::Arc<#ident>;
            fn view_archived(
                value: &::esgm_core::codec::ArchivedValue,
            ) -> ::std::option::Option<::std::sync::Arc<#ident>> {
                ::esgm_core::entity_view::view_nested_archived(value)
            }
            fn view_value(
                value: &::esgm_core::Value,
            ) -> ::std::option::Option<::std::sync::Arc<#ident>> {
                ::esgm_core::entity_view::view_nested(value)
            }
        }

        /// A typed entity nests as a frame whose element type is its own.
        impl ::esgm_core::AttributeField for #ident {
            const SORT: ::esgm_core::ValueSort = ::esgm_core::ValueSort::EntityFrame;
            fn element_type() -> ::std::option::Option<&'static str> {
                ::std::option::Option::Some(#type_name)
            }
            fn to_value(&self) -> ::esgm_core::Value {
                ::esgm_core::Value::EntityFrame(::std::boxed::Box::new(
                    ::esgm_core::Entity::to_frame(self, #type_name),
                ))
            }
            fn from_value_ref(
                value: ::esgm_core::ValueRef<'_>,
            ) -> ::std::option::Option<Self> {
                value
                    .as_frame()
                    .and_then(|f| <Self as ::esgm_core::Entity>::from_frame_ref(f).ok())
            }
        }
    })
}
